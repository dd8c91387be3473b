# Source me: Open MPI settings for running as root in containers/CI and on small machines.
if [ "$(id -u)" -eq 0 ]; then
  export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
fi
export OMPI_MCA_rmaps_base_oversubscribe=1
# One machine: shared memory between ranks, no TCP. Open MPI 5 (Debian 13) otherwise probes every
# interface and prints "Unable to find reachable pairing between local and remote interfaces" when a
# down bridge (docker0 with a container attached) is among them.
export OMPI_MCA_btl=^tcp
# Single-threaded BLAS per rank: MPI ranks are the parallelism.
export OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1
HB_MPIRUN_FLAGS="--oversubscribe"
