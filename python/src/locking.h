// Locks for objects shared between Python threads.
#pragma once

#include <pybind11/pybind11.h>

#include <mutex>

namespace qpreduce::python {

// Takes `mutex` as a Lock (std::unique_lock, std::shared_lock), holding on to
// the GIL when the mutex is free and letting go of it while waiting, so that
// a thread holding the mutex with the GIL released can always finish.
template <typename Lock, typename Mutex>
Lock lock_releasing_gil(Mutex& mutex) {
  Lock lock(mutex, std::try_to_lock);
  if (!lock.owns_lock()) {
    pybind11::gil_scoped_release release;
    lock.lock();
  }
  return lock;
}

}  // namespace qpreduce::python
