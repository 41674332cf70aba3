// SIGINT and SIGTERM as a request to stop: while an InterruptHandlers lives, the first signal
// only sets a flag, which `fastslam run` reads between events and then ends the run as at the
// end of its data, writing what it has; a second signal ends the process at once (the default
// action). Handlers use SA_RESTART, so a run blocked reading a pipe notices at its next record.
// A signal ignored when the handlers are installed (nohup, a background job) stays ignored.
//
// The flag is process-wide, as signal dispositions are. Thread safety: construct and destroy
// on one thread; interrupt_signal() may be read from any. Costs: O(1).
#pragma once

namespace fastslam::tools {

class InterruptHandlers {
 public:
  // Installs the handlers and clears the flag; the destructor restores the previous handlers
  // and clears it again.
  InterruptHandlers();
  ~InterruptHandlers();
  InterruptHandlers(const InterruptHandlers&) = delete;
  InterruptHandlers& operator=(const InterruptHandlers&) = delete;
};

// The signal that asked to stop (SIGINT or SIGTERM), 0 when none did.
int interrupt_signal();

// "SIGINT", "SIGTERM", or "signal N".
const char* interrupt_name(int signal);

}  // namespace fastslam::tools
