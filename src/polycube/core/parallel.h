// Two-way parallelism for this project's 2-core target: run two independent tasks side by side,
// with the BLAS (OpenBLAS, if that is the one loaded) kept to one thread meanwhile.
#pragma once
#include <exception>
#include <memory>
#include <string>
#include <thread>

namespace polycube {

/// Cores used: 1 or 2 (more do not pay at our sizes: memory-bound solves, small dense kernels):
/// the machine's, at most 2, lowered by set_thread_limit or else by the environment variable
/// POLYCUBE_THREADS (read at the first call).
int hardware_threads();

/// Limits the cores used to n (1 or 2; 0 lifts the limit, back to POLYCUBE_THREADS or the
/// machine's); OpenBLAS's thread count follows at once (set_blas_threads; run_pipeline sets it
/// again at its start, also for the environment's limit). Set it before the work starts: the two
/// counts round differently (OpenBLAS's factorizations), so a run is reproduced bit for bit only at
/// the same count. One core pays where
/// other jobs share the machine: OpenBLAS's threads spin while they wait for each other, and a
/// busy second core slows them down several times (fandisk's deformation, 35.6k tets, on 2 cores:
/// alone 7.2 s with two threads, 12.0 s with one; beside one busy process 20.0-20.3 s with two,
/// 12.1-13.0 s with one, the numeric factorizations 10.2-10.4 s against 3.1-3.3 s).
void set_thread_limit(int n);

/// The kernels OpenBLAS runs, by its core name ("Haswell", "Zen", "SkylakeX", ...); empty when the
/// loaded BLAS is not OpenBLAS.
std::string blas_core();

/// For executables, first thing in main(). OpenBLAS picks its kernels per CPU when it loads, and
/// kernels round differently: the same input gave other deformations, polycubes and meshes on an
/// AVX-512 machine than on an AVX2 one (box_hole's hexes: Hausdorff 2.59e-3 against 2.54e-3;
/// fandisk's surface polycube: ARAP 0.037 against 0.097). On a CPU with AVX2 and FMA, unless the
/// environment sets OPENBLAS_CORETYPE already, this sets it to Haswell (the AVX2 kernels, which
/// Intel CPUs since 2013 and AMD's since Zen run) and executes the program again with the same
/// arguments, so that results are the same bits on every such machine. Returns only when it did
/// not execute the program again (environment set, no AVX2, or the exec failed).
void reexec_with_portable_blas(char** argv);

/// Sets OpenBLAS's thread count, at most hardware_threads(), if the loaded BLAS is OpenBLAS (looked
/// up at run time, so that any other BLAS works too); no effect otherwise. While a run_pair runs
/// (in any thread), the count stays 1 whatever n is: OpenBLAS rounds differently with one thread
/// and with two (its dpotrf blocks otherwise), so a task that factorized with two threads once the
/// other task had ended gave results that depended on which task ended first (the realization's
/// two starts: spot's polycube differed under load).
void set_blas_threads(int n);

/// While an instance exists (in any thread), OpenMP parallel regions run on one thread; the setting
/// before the first instance returns when the last one ends. For CHOLMOD's factorizations: the
/// Debian build (SuiteSparse 5) opens teams with a compiled-in num_threads(4), which
/// omp_set_num_threads cannot lower, for loops as small as zeroing one supernode, so every
/// factorization ran four OpenMP threads beside OpenBLAS's two on two cores (fandisk, 39k tets,
/// 6 factorizations: 2.2-2.3 s with the teams, 1.3-1.6 s without, the same factors). Gmsh's
/// meshing, outside these scopes, keeps its threads.
class SerialOpenMP {
 public:
  SerialOpenMP();
  ~SerialOpenMP();
  SerialOpenMP(const SerialOpenMP&) = delete;
  SerialOpenMP& operator=(const SerialOpenMP&) = delete;
};

namespace detail {
/// run_pair calls in progress (the BLAS keeps one thread while any is).
void enter_pair();
void leave_pair();  // restores the BLAS to hardware_threads() when the last one ends

/// The second core's persistent worker. Starting a thread per task cost 0.2-0.3 ms on this
/// project's virtual machine, against tasks of 1-3 ms (the preconditioner's sweeps, several per CG
/// iteration). One task at a time: claim() returns false while another caller holds the worker
/// (run_pair from inside a run_pair task), and that caller then starts a thread as before.
class PairWorker {
 public:
  static PairWorker& instance();
  bool claim();
  /// Runs fn(arg) on the worker; wait() returns once it has finished. Only after claim().
  void start(void (*fn)(void*), void* arg);
  void wait();  // also releases the claim
 private:
  PairWorker();
  ~PairWorker();
  void loop();
  struct State;
  std::unique_ptr<State> s_;
};
}  // namespace detail

/// Runs f(0) on this thread and f(1) on another when the machine has two cores (one after the
/// other otherwise), with a single-threaded BLAS meanwhile (restored to hardware_threads() after).
/// An exception of either task is rethrown after both have finished. f(1) runs on a persistent
/// worker thread when that is free, on a new thread otherwise.
template <class F>
void run_pair(F&& f) {
  if (hardware_threads() < 2) {
    // One after the other, with the same contract: both run, the first exception after both.
    std::exception_ptr first;
    try {
      f(0);
    } catch (...) {
      first = std::current_exception();
    }
    try {
      f(1);
    } catch (...) {
      if (!first) first = std::current_exception();
    }
    if (first) std::rethrow_exception(first);
    return;
  }
  detail::enter_pair();
  std::exception_ptr failure;
  auto second = [&] {
    try {
      f(1);
    } catch (...) {
      failure = std::current_exception();
    }
  };
  using Second = decltype(second);
  auto& worker = detail::PairWorker::instance();
  const bool pooled = worker.claim();
  std::thread other;
  if (pooled)
    worker.start([](void* a) { (*static_cast<Second*>(a))(); }, &second);
  else
    other = std::thread(second);
  auto join = [&] {
    if (pooled)
      worker.wait();
    else
      other.join();
    detail::leave_pair();
  };
  try {
    f(0);
  } catch (...) {
    join();
    throw;
  }
  join();
  if (failure) std::rethrow_exception(failure);
}

}  // namespace polycube
