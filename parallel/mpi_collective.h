// The group of MPI ranks as a parallel::Collective (parallel/collective.h): a Filter built with
// it spreads its particle set over the ranks of MPI_COMM_WORLD. all_gather is MPI_Allgather of
// the lengths then MPI_Allgatherv; exchange is MPI_Alltoall of the lengths then MPI_Alltoallv.
// Available when the build found MPI (Open MPI: libopenmpi-dev; the library fastslam::mpi).
// Ownership: the caller initialises MPI before and finalises it after every object made here
// is gone; the collective owns a duplicate of MPI_COMM_WORLD, so its messages never meet the
// caller's. Thread safety: one thread of the rank uses it (MPI_THREAD_SERIALIZED suffices).
// Costs: two MPI collectives per call; a contribution or message is limited to 2^31 - 1 bytes
// (std::length_error beyond).
#pragma once

#include <cstddef>
#include <memory>

#include "parallel/collective.h"

namespace fastslam::parallel {

// REQUIRES: MPI initialised. Throws std::runtime_error when MPI is not initialised.
std::shared_ptr<Collective> mpi_world();

// `bytes` as an MPI count; throws std::length_error beyond MPI's int limit.
int mpi_count(std::size_t bytes);

}  // namespace fastslam::parallel
