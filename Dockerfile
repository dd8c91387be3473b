# hydrobuckle with the Debian FEniCSx stack: Debian 13 by default (dolfinx 0.9.0, PETSc/SLEPc 3.22,
# gmsh 4.13, Python 3.13), Debian 12 with a build argument (dolfinx 0.5.2, PETSc/SLEPc 3.18, gmsh 4.8).
#   docker build -t hydrobuckle .
#   docker build --build-arg BASE=debian:bookworm -t hydrobuckle:bookworm .
#   mkdir -p results
#   docker run --rm --user "$(id -u):$(id -g)" -v "$PWD/results:/opt/hydrobuckle/results" \
#       hydrobuckle mpirun -n 2 hydrobuckle run configs/bilayer.toml
# scripts/docker-check.sh builds both images (making the debian:trixie and debian:bookworm bases with
# debootstrap where they cannot be pulled) and checks these commands on each.
ARG BASE=debian:trixie
FROM ${BASE}
ENV DEBIAN_FRONTEND=noninteractive \
    OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
    OMPI_MCA_rmaps_base_oversubscribe=1 \
    OMPI_MCA_btl_vader_single_copy_mechanism=none \
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 \
    XDG_CACHE_HOME=/var/cache/hydrobuckle \
    MPLCONFIGDIR=/var/cache/hydrobuckle/matplotlib
# OMPI_MCA_btl_vader_single_copy_mechanism=none: the container's security profile blocks Open MPI's
# shared-memory single copy (thousands of "Read -1, expected ..." lines without it).
# XDG_CACHE_HOME, MPLCONFIGDIR: the form (JIT) and matplotlib caches, writable for any --user uid,
# warmed while building.
WORKDIR /opt/hydrobuckle
# System stack: this layer depends only on the package list (and its installer), not on the code.
COPY scripts/apt-packages*.txt scripts/apt-install.sh scripts/
RUN APT_CLEAN=1 bash scripts/apt-install.sh
COPY . .
RUN rm -rf .venv && mkdir -p "$XDG_CACHE_HOME" "$MPLCONFIGDIR" \
    && bash scripts/install.sh \
    && chmod -R a+rwX "$XDG_CACHE_HOME" && chmod 1777 "$XDG_CACHE_HOME"
ENV PATH=/opt/hydrobuckle/.venv/bin:$PATH
ENTRYPOINT ["/opt/hydrobuckle/scripts/docker-entrypoint.sh"]
CMD ["--help"]
