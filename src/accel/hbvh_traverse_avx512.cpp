// The HBVH traversal kernels for AVX-512 (hbvh_kernels.h): the AVX2 kernels' 256-bit registers
// with AVX-512F/VL/BW/DQ (mask registers, vpcompressd), built with those flags (CMakeLists.txt)
// and called only where the CPU has them.

#define VOXCONE_ISA avx512
#include "hbvh_traverse_kernel.h"

#if !defined(__AVX2__) || !defined(__AVX512VL__)
#error "hbvh_traverse_avx512.cpp must be compiled with -mavx2 -mavx512f -mavx512vl"
#endif
