// The test binary's main: the same BLAS kernels as the CLI (core/parallel.h), so that the figures
// the real-data tests check are the same bits on every AVX2 machine, then GoogleTest.
#include <gtest/gtest.h>

#include "polycube/core/parallel.h"

int main(int argc, char** argv) {
  polycube::reexec_with_portable_blas(argv);
  ::testing::InitGoogleTest(&argc, argv);
  return RUN_ALL_TESTS();
}
