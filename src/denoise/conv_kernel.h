#pragma once
/// \file conv_kernel.h
/// The denoiser's 3x3 convolution over channel-blocked tensors, written once and compiled per
/// instruction set (conv_generic.cpp with the library's flags, conv_avx2.cpp with AVX2 and FMA;
/// unet.cpp chooses at run time). Each output value is a sum in a fixed order (input block,
/// kernel row, kernel column, channel), so the result does not depend on how rows are shared
/// among threads.

#include <cstddef>

namespace voxcone::denoise {

/// Channels per block: one 8-float vector (AVX2's width), two of SSE's.
constexpr int kBlock = 8;

/// A tensor's view for one convolution: `blocks` channel blocks of (h + 2) x (w + 2) pixels of
/// kBlock floats (a zero border of one pixel all round), block b at data + b * blockStride.
struct TensorView {
  float* data = nullptr;
  int blocks = 0;
  int h = 0, w = 0;
  size_t blockStride = 0;
  float* pixel(int b, int y, int x) const {
    return data + size_t(b) * blockStride + (size_t(y + 1) * size_t(w + 2) + size_t(x + 1)) * kBlock;
  }
};

/// One output row pair of blocks: out blocks ob and ob + 1 (where ob + 1 < out.blocks) of row y,
/// from all of in's blocks. Weights are [out block][in block][ky][kx][in channel][out channel]
/// (kBlock x kBlock floats per (ob, ib, ky, kx)); bias per output channel; then ReLU, max(0, x)
/// (every layer of the RT network has it, dec_conv0 included, as OIDN 2 builds it).
using ConvRowFn = void (*)(const TensorView& in, const TensorView& out, const float* weights, const float* bias,
                           int ob, int y);

#ifdef VOXCONE_CONV_KERNEL_NAMESPACE
namespace VOXCONE_CONV_KERNEL_NAMESPACE {

namespace {

/// The vector this kernel is built for: VOXCONE_CONV_LANES floats (8: AVX2; 4: SSE, where an
/// 8-float vector was split so poorly that the kernel ran at 2.5 Gflop/s), a block in kParts.
constexpr int kLanes = VOXCONE_CONV_LANES;
constexpr int kParts = kBlock / kLanes;
typedef float VecL __attribute__((vector_size(4 * kLanes)));

/// s in every lane (not VecL{} + s: a sum with 0 the compiler must keep, for s = -0).
inline VecL splat(float s) {
#if VOXCONE_CONV_LANES == 8
  return VecL{s, s, s, s, s, s, s, s};
#else
  return VecL{s, s, s, s};
#endif
}

/// XB output pixels of two output blocks (or one, Two false) starting at x0.
template <int XB, bool Two>
inline void convPixels(const TensorView& in, const TensorView& out, const float* weights, const float* bias, int ob,
                       int y, int x0) {
  VecL acc0[XB][kParts], acc1[XB][kParts];
  for (int p = 0; p < kParts; ++p) {
    VecL b0, b1 = {};
    __builtin_memcpy(&b0, bias + size_t(ob) * kBlock + size_t(p) * kLanes, sizeof b0);
    if constexpr (Two) __builtin_memcpy(&b1, bias + size_t(ob + 1) * kBlock + size_t(p) * kLanes, sizeof b1);
    for (int i = 0; i < XB; ++i) {
      acc0[i][p] = b0;
      acc1[i][p] = b1;
    }
  }
  const size_t perOut = size_t(in.blocks) * 9 * kBlock * kBlock;
  const float* w0 = weights + size_t(ob) * perOut;
  const float* w1 = Two ? w0 + perOut : w0;
  const size_t rowStride = size_t(in.w + 2) * kBlock;
  for (int ib = 0; ib < in.blocks; ++ib) {
    // Padded row y (the output row's upper neighbour) at padded column x0.
    const float* base = in.data + size_t(ib) * in.blockStride + (size_t(y) * size_t(in.w + 2) + size_t(x0)) * kBlock;
    for (int ky = 0; ky < 3; ++ky) {
      const float* row = base + size_t(ky) * rowStride;
      for (int kx = 0; kx < 3; ++kx) {
        const float* src = row + size_t(kx) * kBlock;
        const size_t wOff = ((size_t(ib) * 3 + size_t(ky)) * 3 + size_t(kx)) * kBlock * kBlock;
        for (int c = 0; c < kBlock; ++c) {
          VecL wa[kParts], wb[kParts] = {};
          for (int p = 0; p < kParts; ++p) {
            __builtin_memcpy(&wa[p], w0 + wOff + size_t(c) * kBlock + size_t(p) * kLanes, sizeof(VecL));
            if constexpr (Two) __builtin_memcpy(&wb[p], w1 + wOff + size_t(c) * kBlock + size_t(p) * kLanes, sizeof(VecL));
          }
          for (int i = 0; i < XB; ++i) {
            const VecL v = splat(src[size_t(i) * kBlock + size_t(c)]);
            for (int p = 0; p < kParts; ++p) {
              acc0[i][p] += v * wa[p];
              if constexpr (Two) acc1[i][p] += v * wb[p];
            }
          }
        }
      }
    }
  }
  const VecL zero = {};
  for (int i = 0; i < XB; ++i)
    for (int p = 0; p < kParts; ++p) {
      acc0[i][p] = acc0[i][p] > zero ? acc0[i][p] : zero;
      acc1[i][p] = acc1[i][p] > zero ? acc1[i][p] : zero;
      __builtin_memcpy(out.pixel(ob, y, x0 + i) + p * kLanes, &acc0[i][p], sizeof(VecL));
      if constexpr (Two) __builtin_memcpy(out.pixel(ob + 1, y, x0 + i) + p * kLanes, &acc1[i][p], sizeof(VecL));
    }
}

template <bool Two>
inline void convRowImpl(const TensorView& in, const TensorView& out, const float* weights, const float* bias, int ob,
                        int y) {
  // 2 blocks x kParts vectors x kX pixels: 12 accumulators, the weights and a broadcast in 16
  // registers.
  constexpr int kX = 6 / kParts;
  int x = 0;
  for (; x + kX <= out.w; x += kX) convPixels<kX, Two>(in, out, weights, bias, ob, y, x);
  switch (out.w - x) {
    case 5: convPixels<5, Two>(in, out, weights, bias, ob, y, x); break;
    case 4: convPixels<4, Two>(in, out, weights, bias, ob, y, x); break;
    case 3: convPixels<3, Two>(in, out, weights, bias, ob, y, x); break;
    case 2: convPixels<2, Two>(in, out, weights, bias, ob, y, x); break;
    case 1: convPixels<1, Two>(in, out, weights, bias, ob, y, x); break;
    default: break;
  }
}

}  // namespace

void convRow(const TensorView& in, const TensorView& out, const float* weights, const float* bias, int ob, int y) {
  if (ob + 1 < out.blocks) convRowImpl<true>(in, out, weights, bias, ob, y);
  else convRowImpl<false>(in, out, weights, bias, ob, y);
}

}  // namespace VOXCONE_CONV_KERNEL_NAMESPACE
#endif

namespace generic {
void convRow(const TensorView& in, const TensorView& out, const float* weights, const float* bias, int ob, int y);
}
namespace avx2 {
void convRow(const TensorView& in, const TensorView& out, const float* weights, const float* bias, int ob, int y);
}

}  // namespace voxcone::denoise
