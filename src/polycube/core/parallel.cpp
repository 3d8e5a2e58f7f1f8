#include "polycube/core/parallel.h"

#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <mutex>

namespace polycube {

namespace {
std::atomic<int> thread_limit{0};
}  // namespace

int hardware_threads() {
  static const int machine = static_cast<int>(std::max(1u, std::min(2u, std::thread::hardware_concurrency())));
  static const int from_environment = [] {
    const char* e = std::getenv("POLYCUBE_THREADS");
    return e ? std::atoi(e) : 0;
  }();
  const int set = thread_limit.load(std::memory_order_relaxed);
  const int limit = set > 0 ? set : from_environment;
  return limit >= 1 ? std::min(machine, limit) : machine;
}

std::string blas_core() {
  using GetName = char* (*)();
  static const auto f = reinterpret_cast<GetName>(dlsym(RTLD_DEFAULT, "openblas_get_corename"));
  const char* name = f ? f() : nullptr;
  return name ? std::string(name) : std::string();
}

void reexec_with_portable_blas(char** argv) {
#if defined(__x86_64__) && defined(__linux__)
  if (std::getenv("OPENBLAS_CORETYPE") != nullptr) return;
  __builtin_cpu_init();
  if (!__builtin_cpu_supports("avx2") || !__builtin_cpu_supports("fma")) return;
  if (setenv("OPENBLAS_CORETYPE", "Haswell", 1) != 0) return;
  execv("/proc/self/exe", argv);
  unsetenv("OPENBLAS_CORETYPE");  // the exec failed: go on with the kernels loaded
#else
  (void)argv;
#endif
}

namespace {
std::mutex& blas_mutex() {
  static std::mutex m;
  return m;
}
int pair_depth = 0;  // guarded by blas_mutex()
void apply_blas_threads(int n) {
  using SetThreads = void (*)(int);
  static const auto f = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
  if (f) f(n);
}
}  // namespace

void set_blas_threads(int n) {
  const std::lock_guard<std::mutex> lock(blas_mutex());
  apply_blas_threads(pair_depth > 0 ? 1 : std::min(n, hardware_threads()));
}

void set_thread_limit(int n) {
  thread_limit.store(std::max(0, n), std::memory_order_relaxed);
  set_blas_threads(hardware_threads());  // at once: not only from the next factorization on
}

namespace detail {
void enter_pair() {
  const std::lock_guard<std::mutex> lock(blas_mutex());
  if (pair_depth++ == 0) apply_blas_threads(1);
}
void leave_pair() {
  const std::lock_guard<std::mutex> lock(blas_mutex());
  if (--pair_depth == 0) apply_blas_threads(hardware_threads());
}
}  // namespace detail

namespace {
struct OpenMPLevels {
  std::mutex mutex;
  int depth = 0, saved = 0;
  using Get = int (*)();
  using Set = void (*)(int);
  Get get = reinterpret_cast<Get>(dlsym(RTLD_DEFAULT, "omp_get_max_active_levels"));
  Set set = reinterpret_cast<Set>(dlsym(RTLD_DEFAULT, "omp_set_max_active_levels"));
};
OpenMPLevels& openmp_levels() {
  static OpenMPLevels l;
  return l;
}
}  // namespace

SerialOpenMP::SerialOpenMP() {
  auto& l = openmp_levels();
  if (!l.get || !l.set) return;
  const std::lock_guard<std::mutex> lock(l.mutex);
  if (l.depth++ == 0) {
    l.saved = l.get();
    l.set(0);  // no active parallel region: every team has one thread
  }
}

SerialOpenMP::~SerialOpenMP() {
  auto& l = openmp_levels();
  if (!l.get || !l.set) return;
  const std::lock_guard<std::mutex> lock(l.mutex);
  if (--l.depth == 0) l.set(l.saved);
}

namespace detail {

// Handshake: `posted` counts tasks given to the worker, `done` tasks it has finished. Both sides
// spin for a while before sleeping on the atomic (a futex): the sweeps' tasks follow each other
// within a millisecond, and a futex wake-up costs tens of microseconds on a virtual machine. The
// spin is bounded, so that an idle worker does not take the core from the BLAS's threads during a
// factorization.
struct PairWorker::State {
  std::atomic<bool> claimed{false};
  std::atomic<unsigned> posted{0}, done{0};
  std::atomic<bool> stop{false};
  void (*fn)(void*) = nullptr;
  void* arg = nullptr;
  std::thread thread;
};

namespace {

inline void cpu_relax() {
#if defined(__x86_64__) || defined(__i386__)
  __builtin_ia32_pause();
#endif
}

// Spins until value != seen or about `micros` have passed; then sleeps until it changes.
void await_change(const std::atomic<unsigned>& value, unsigned seen, int micros) {
  const auto until = std::chrono::steady_clock::now() + std::chrono::microseconds(micros);
  for (int i = 0;; ++i) {
    if (value.load(std::memory_order_acquire) != seen) return;
    if ((i & 63) == 63 && std::chrono::steady_clock::now() > until) break;
    cpu_relax();
  }
  while (value.load(std::memory_order_acquire) == seen) value.wait(seen, std::memory_order_acquire);
}

}  // namespace

PairWorker& PairWorker::instance() {
  static PairWorker w;
  return w;
}

PairWorker::PairWorker() : s_(std::make_unique<State>()) { s_->thread = std::thread([this] { loop(); }); }

PairWorker::~PairWorker() {
  s_->stop.store(true);
  s_->posted.fetch_add(1, std::memory_order_release);
  s_->posted.notify_one();
  s_->thread.join();
}

void PairWorker::loop() {
  unsigned seen = 0;
  for (;;) {
    await_change(s_->posted, seen, 1000);
    seen = s_->posted.load(std::memory_order_acquire);
    if (s_->stop.load()) return;
    s_->fn(s_->arg);
    s_->done.store(seen, std::memory_order_release);
    s_->done.notify_one();
  }
}

bool PairWorker::claim() { return !s_->claimed.exchange(true, std::memory_order_acquire); }

void PairWorker::start(void (*fn)(void*), void* arg) {
  s_->fn = fn;
  s_->arg = arg;
  s_->posted.fetch_add(1, std::memory_order_release);
  s_->posted.notify_one();
}

void PairWorker::wait() {
  const unsigned target = s_->posted.load(std::memory_order_relaxed);
  for (unsigned d = s_->done.load(std::memory_order_acquire); d != target; d = s_->done.load(std::memory_order_acquire))
    await_change(s_->done, d, 2000);
  s_->claimed.store(false, std::memory_order_release);
}

}  // namespace detail

}  // namespace polycube
