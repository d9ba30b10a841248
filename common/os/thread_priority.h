// Scheduling for threads we do not create ourselves. Threads inherit the scheduling policy and priority of the
// thread that starts them, and Fast DDS 2.9 has no setting for its threads' priority: so a node raises its own
// thread to SCHED_FIFO while it creates the DDS participant, readers and writers (their receive and event threads
// are started then), and returns to its previous scheduling afterwards. A contact frame or a device command then
// preempts rendering or model work the moment it arrives, instead of waiting for a time slice.
#pragma once
#include <sched.h>

#include <string>

namespace surgsim::os {

class ScopedFifo {
 public:
  /// priority in 1..99 raises the calling thread to SCHED_FIFO (when permitted); 0 leaves it alone.
  explicit ScopedFifo(int priority);
  /// Restores the calling thread's previous policy and priority. Call from the thread that made this object.
  ~ScopedFifo();
  ScopedFifo(const ScopedFifo&) = delete;
  ScopedFifo& operator=(const ScopedFifo&) = delete;

  bool raised() const { return raised_; }
  /// e.g. "SCHED_FIFO 20", "normal scheduling (priority 0)", "normal scheduling (SCHED_FIFO refused: ...)".
  const std::string& note() const { return note_; }

 private:
  int policy_ = SCHED_OTHER;
  sched_param param_{};
  bool raised_ = false;
  std::string note_;
};

}  // namespace surgsim::os
