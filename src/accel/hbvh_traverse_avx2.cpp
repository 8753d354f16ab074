// The HBVH traversal kernels for AVX2 (hbvh_kernels.h): built with -mavx2 -mfma and
// -ffp-contract=off (CMakeLists.txt: no product and sum fused unless the kernel asks, so every
// product rounds as in the SSE kernels) and called only where the CPU has AVX2 and FMA.

#define VOXCONE_ISA avx2
#include "hbvh_traverse_kernel.h"

#ifndef __AVX2__
#error "hbvh_traverse_avx2.cpp must be compiled with -mavx2"
#endif
