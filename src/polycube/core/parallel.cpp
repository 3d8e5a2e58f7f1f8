#include "polycube/core/parallel.h"

#include <dlfcn.h>

#include <algorithm>

namespace polycube {

int hardware_threads() { return static_cast<int>(std::max(1u, std::min(2u, std::thread::hardware_concurrency()))); }

void set_blas_threads(int n) {
  using SetThreads = void (*)(int);
  static const auto f = reinterpret_cast<SetThreads>(dlsym(RTLD_DEFAULT, "openblas_set_num_threads"));
  if (f) f(n);
}

}  // namespace polycube
