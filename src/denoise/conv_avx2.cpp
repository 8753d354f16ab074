// The denoiser's convolution with AVX2 and FMA (conv_kernel.h; chosen at run time where the
// CPU has both).
#define VOXCONE_CONV_KERNEL_NAMESPACE avx2
#define VOXCONE_CONV_LANES 8
#include "conv_kernel.h"
