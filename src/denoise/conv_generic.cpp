// The denoiser's convolution with the library's own flags (conv_kernel.h).
#define VOXCONE_CONV_KERNEL_NAMESPACE generic
#include "conv_kernel.h"
