# hydrobuckle on Debian 12 with the Debian FEniCSx stack (dolfinx 0.5.2, PETSc/SLEPc 3.18, gmsh 4.8).
#   docker build -t hydrobuckle .
#   docker run --rm -v "$PWD/results:/opt/hydrobuckle/results" hydrobuckle mpirun -n 2 hydrobuckle run configs/bilayer.toml
FROM debian:bookworm
ENV DEBIAN_FRONTEND=noninteractive \
    OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 \
    OMPI_MCA_rmaps_base_oversubscribe=1 OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
WORKDIR /opt/hydrobuckle
# Install the system stack first (cached layer), then the project itself.
COPY scripts/install.sh scripts/install.sh
RUN HYDROBUCKLE_SYSTEM_ONLY=1 bash scripts/install.sh && rm -rf /var/lib/apt/lists/*
COPY . .
RUN rm -rf .venv && bash scripts/install.sh
ENV PATH=/opt/hydrobuckle/.venv/bin:$PATH
ENTRYPOINT ["/opt/hydrobuckle/scripts/docker-entrypoint.sh"]
CMD ["--help"]
