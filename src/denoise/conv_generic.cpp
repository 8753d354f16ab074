// The denoiser's convolution with the library's own flags (conv_kernel.h).
#define VOXCONE_CONV_KERNEL_NAMESPACE generic
#define VOXCONE_CONV_LANES 4
#include "conv_kernel.h"
