// Two-way parallelism for this project's 2-core target: run two independent tasks side by side,
// with the BLAS (OpenBLAS, if that is the one loaded) kept to one thread meanwhile.
#pragma once
#include <exception>
#include <thread>

namespace polycube {

/// Cores used: 1 or 2 (more do not pay at our sizes: memory-bound solves, small dense kernels).
int hardware_threads();

/// Sets OpenBLAS's thread count if the loaded BLAS is OpenBLAS (looked up at run time, so that
/// any other BLAS works too); no effect otherwise.
void set_blas_threads(int n);

/// Runs f(0) on this thread and f(1) on another when the machine has two cores (one after the
/// other otherwise), with a single-threaded BLAS meanwhile (restored to hardware_threads() after).
/// An exception of either task is rethrown after both have finished.
template <class F>
void run_pair(F&& f) {
  if (hardware_threads() < 2) {
    f(0);
    f(1);
    return;
  }
  set_blas_threads(1);
  std::exception_ptr failure;
  std::thread other([&] {
    try {
      f(1);
    } catch (...) {
      failure = std::current_exception();
    }
  });
  try {
    f(0);
  } catch (...) {
    other.join();
    set_blas_threads(hardware_threads());
    throw;
  }
  other.join();
  set_blas_threads(hardware_threads());
  if (failure) std::rethrow_exception(failure);
}

}  // namespace polycube
