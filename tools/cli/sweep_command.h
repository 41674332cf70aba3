// `fastslam sweep`: the runs of a sweep plan (tools/cli/sweep_grid.h) spread over local worker
// threads (--jobs) and, under `mpirun`, over MPI ranks, then gathered into OUT/sweep.json (the
// provenance once, every run's metrics, a summary per configuration) and OUT/sweep.csv (a row
// per run). Each run is `fastslam run` with its options into OUT/NAME/seed-S (run_entry,
// tools/cli/run_sweep.h, the code `fastslam run --seeds` uses), so a run's results do not depend
// on where or beside what it ran, only its timings do.
//
// Scheduling is dynamic, largest first (SweepRun::cost): a worker takes the next run when it
// is free. Under MPI rank 0 hands out run indices (MPI_Send/Recv) to every rank's workers,
// including its own, and receives each run's metrics as JSON text; every rank writes its runs'
// files itself (OUT must be a directory all ranks see). Before any run, every rank plans the
// sweep and hashes its inputs; a rank that cannot (a missing file) or whose plan differs from
// rank 0's (SHA-256 of the file, the arguments and the inputs) makes every rank exit 1, rank 0
// naming the ranks and the reason; none is left waiting. A run that fails stops the sweep: no
// run starts after it, the runs under way finish, the files are written and every rank exits
// 1. SIGINT or SIGTERM (mpirun forwards them) end the runs under way as `fastslam run` does.
//
// Resume: a run whose OUT/NAME/seed-S/metrics.json says "status": "complete" and holds the same
// identity ("sweep_run": the build, the options that change results, the inputs' SHA-256) is not
// run again; its metrics are read back, so the tables equal an uninterrupted sweep's.
//
// MPI is used when the build found it (FASTSLAM_HAVE_MPI) and the process was started by a
// launcher (OMPI_COMM_WORLD_SIZE, PMIX_RANK or PMI_SIZE in the environment); otherwise the
// sweep runs in this process alone.
//
// Ownership: plain options in; files out. Thread safety: one sweep per process (it installs
// the interrupt handlers and, under MPI, initialises MPI). Costs: the runs'; rank 0 polls for
// messages every millisecond or so (Open MPI's blocking receive would spin a core).
#pragma once

#include "tools/cli/sweep_grid.h"

namespace fastslam::tools {

struct SweepOptions {
  SweepRequest request;
  // Runs at once in each process; 0: the hardware threads / the ranks on this node / each
  // run's --threads (at least 1).
  unsigned jobs = 0;
  bool dry_run = false;  // print the plan (runs, order, what is done) and run nothing
};

// Runs the sweep; returns the process exit code: 0; 1 when the sweep was refused or a run
// failed (the message printed on stderr by rank 0, or by the rank that alone could not plan
// it); or 128 + the signal when interrupted.
int run_sweep_command(const SweepOptions& options);

}  // namespace fastslam::tools
