#include "os/thread_priority.h"

#include <pthread.h>

#include <cstring>

namespace surgsim::os {

ScopedFifo::ScopedFifo(int priority) {
  // pthread_*schedparam, not sched_*: glibc caches a thread's scheduling and copies that cache into the threads it
  // creates, so the raw system calls would leave new threads reporting the wrong policy.
  pthread_getschedparam(pthread_self(), &policy_, &param_);
  if (priority <= 0) {
    note_ = "normal scheduling (priority 0)";
    return;
  }
  sched_param fifo{};
  fifo.sched_priority = priority;
  const int error = pthread_setschedparam(pthread_self(), SCHED_FIFO, &fifo);
  if (error == 0) {
    raised_ = true;
    note_ = "SCHED_FIFO " + std::to_string(priority);
  } else {
    note_ = std::string("normal scheduling (SCHED_FIFO refused: ") + std::strerror(error) +
            "; run as root or grant CAP_SYS_NICE)";
  }
}

ScopedFifo::~ScopedFifo() {
  if (raised_) pthread_setschedparam(pthread_self(), policy_, &param_);
}

}  // namespace surgsim::os
