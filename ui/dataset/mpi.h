#pragma once
// A dataset spread over MPI ranks (`mpirun -n N sonotrace dataset ...`, or `srun` under
// Slurm). Rank 0 keeps the queue of missing shards and hands the next one to whichever
// rank asks, so a slow rank does not hold the others; it also makes shards itself between
// answering. Each rank uses its cores through the thread pool. Frames are pure functions
// of (spec, index), so the shards are the same bytes whichever rank makes them, and the
// same as a run on one machine. A rank that dies loses only its shard in flight (never
// renamed into place), which the next run makes.
#include "ui/dataset/dataset.h"

namespace sonotrace::dataset {

// True when this process was started by an MPI launcher (Open MPI, PMI or PMIx
// environment variables), so that a plain `sonotrace dataset` never initialises MPI.
bool launched_by_mpi();

// make_dataset over the ranks of MPI_COMM_WORLD (initialised and finalised here); one
// rank runs make_dataset itself. Progress and the report are rank 0's (frames of every
// rank). An error on any rank (a bad directory, a source that does not load, a shard that
// cannot be written) stops the hand-out of shards; every rank finishes its shard in flight,
// then rank 0 throws the first failing rank's error and the others return with `failed`
// set, so the job prints one message and no rank waits for ever. `rank` receives this
// process's rank.
RunReport make_dataset_mpi(const Spec& spec, const RunOptions& options, int* rank);

}  // namespace sonotrace::dataset
