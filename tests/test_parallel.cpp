// run_pair (the persistent second thread) and SerialOpenMP.
#include <dlfcn.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cstdlib>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "polycube/core/parallel.h"

using namespace polycube;

namespace {
int omp_levels() {
  using Get = int (*)();
  static const auto f = reinterpret_cast<Get>(dlsym(RTLD_DEFAULT, "omp_get_max_active_levels"));
  return f ? f() : -1;
}
int blas_threads() {
  using Get = int (*)();
  static const auto f = reinterpret_cast<Get>(dlsym(RTLD_DEFAULT, "openblas_get_num_threads"));
  return f ? f() : -1;
}
}  // namespace

TEST(Parallel, BlasKeepsOneThreadWhileARunPairRuns) {
  if (blas_threads() < 0) GTEST_SKIP() << "the loaded BLAS is not OpenBLAS";
  set_blas_threads(hardware_threads());
  ASSERT_EQ(blas_threads(), hardware_threads());
  std::atomic<int> inside_max{0};
  run_pair([&](int k) {
    // A factorization asks for two threads (deform/sparse_system.cpp): while the pair runs, one.
    if (k == 0) set_blas_threads(2);
    int n = blas_threads();
    for (int seen = inside_max.load(); n > seen && !inside_max.compare_exchange_weak(seen, n);) {
    }
    run_pair([&](int) { set_blas_threads(2); });  // a nested pair ends: still inside the outer one
    n = blas_threads();
    for (int seen = inside_max.load(); n > seen && !inside_max.compare_exchange_weak(seen, n);) {
    }
  });
  EXPECT_EQ(inside_max.load(), 1);
  EXPECT_EQ(blas_threads(), hardware_threads());  // restored once the pair has ended
}

// set_thread_limit(1): one core for everything, run_pair's tasks one after the other on the
// caller's thread and a one-thread BLAS; 0 lifts the limit again.
TEST(Parallel, ThreadLimitOfOneRunsPairsOnOneThread) {
  if (std::getenv("POLYCUBE_THREADS")) GTEST_SKIP() << "POLYCUBE_THREADS sets the count without a limit";
  const int machine = hardware_threads();
  set_thread_limit(1);
  EXPECT_EQ(hardware_threads(), 1);
  std::thread::id ids[2];
  run_pair([&](int k) { ids[k] = std::this_thread::get_id(); });
  EXPECT_EQ(ids[0], std::this_thread::get_id());
  EXPECT_EQ(ids[1], std::this_thread::get_id());
  if (blas_threads() >= 0) {
    set_blas_threads(2);  // a factorization's request: capped at the limit
    EXPECT_EQ(blas_threads(), 1);
  }
  // The one-thread run_pair keeps the contract: both tasks run, the exception comes after both.
  std::atomic<int> finished{0};
  EXPECT_THROW(run_pair([&](int k) {
                 if (k == 0) throw std::runtime_error("task failed");
                 ++finished;
               }),
               std::runtime_error);
  EXPECT_EQ(finished.load(), 1);
  set_thread_limit(5);  // above the machine's: the machine's
  EXPECT_EQ(hardware_threads(), machine);
  set_thread_limit(0);
  EXPECT_EQ(hardware_threads(), machine);
  if (blas_threads() >= 0) set_blas_threads(hardware_threads());
}

TEST(Parallel, BlasKernelsArePinnedOnAvx2Machines) {
  // The test binary's main calls reexec_with_portable_blas, as the CLI and the bench do.
  const std::string core = blas_core();
  if (core.empty()) GTEST_SKIP() << "the loaded BLAS is not OpenBLAS";
  __builtin_cpu_init();
  if (!__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("fma")) {
    GTEST_SKIP() << "no AVX2: OpenBLAS keeps the kernels it picked";
  }
  const char* env = std::getenv("OPENBLAS_CORETYPE");
  ASSERT_NE(env, nullptr) << "reexec_with_portable_blas sets it on an AVX2 machine";
  if (std::string(env) == "Haswell") {  // else the user's own choice
    EXPECT_EQ(core, "Haswell");
  }
}

// Both tasks run, on two threads when the machine has two cores, thousands of times in a row
// (the handshake must not lose a wake-up), with the results visible to the caller afterwards.
TEST(Parallel, RunPairRunsBothTasksEveryTime) {
  constexpr int kRounds = 2000;
  std::vector<long> sums(2, 0);
  std::atomic<int> distinct{0};
  for (int round = 0; round < kRounds; ++round) {
    std::thread::id ids[2];
    run_pair([&](int k) {
      sums[k] += round + k;
      ids[k] = std::this_thread::get_id();
    });
    if (ids[0] != ids[1]) ++distinct;
  }
  const long expected0 = static_cast<long>(kRounds) * (kRounds - 1) / 2;
  EXPECT_EQ(sums[0], expected0);
  EXPECT_EQ(sums[1], expected0 + kRounds);
  if (hardware_threads() >= 2)
    EXPECT_EQ(distinct.load(), kRounds);
  else
    EXPECT_EQ(distinct.load(), 0);
}

// A run_pair inside a run_pair task (the realization's two starts each solving with two threads):
// the worker is taken, so the inner call starts a thread of its own; every task runs once.
TEST(Parallel, NestedRunPairRunsEveryTask) {
  std::atomic<int> count{0};
  for (int round = 0; round < 200; ++round)
    run_pair([&](int) { run_pair([&](int) { ++count; }); });
  EXPECT_EQ(count.load(), 800);
}

// An exception of either task reaches the caller after both finished, and the worker stays usable.
TEST(Parallel, RunPairRethrowsAndRecovers) {
  for (int thrower = 0; thrower < 2; ++thrower) {
    std::atomic<int> finished{0};
    EXPECT_THROW(run_pair([&](int k) {
                   if (k == thrower) throw std::runtime_error("task failed");
                   ++finished;
                 }),
                 std::runtime_error);
    EXPECT_EQ(finished.load(), 1);
  }
  int ran = 0;
  run_pair([&](int k) {
    if (k == 1) ran = 1;
  });
  EXPECT_EQ(ran, 1);
}

// SerialOpenMP turns OpenMP's active levels to 0 while any instance lives, nested or not, and
// restores the setting from before the first one.
TEST(Parallel, SerialOpenMPRestoresTheSetting) {
  const int before = omp_levels();
  if (before < 0) GTEST_SKIP() << "no OpenMP runtime loaded";
  {
    const SerialOpenMP a;
    EXPECT_EQ(omp_levels(), 0);
    {
      const SerialOpenMP b;
      EXPECT_EQ(omp_levels(), 0);
    }
    EXPECT_EQ(omp_levels(), 0);
  }
  EXPECT_EQ(omp_levels(), before);
}
