#pragma once
/// \file denoiser.h
/// A learned denoiser for HDR renders: Open Image Denoise's "RT" U-Net (Áfra, Intel), its
/// published weights (.tza, tools/fetch_models.sh brings them; never committed) run by our own
/// code on the CPU. As OIDN defines the filter: the colour scaled by autoexposure (0.18 over the
/// geometric mean of 16x16-block luminances) and mapped by the PU transfer function (Aydin et
/// al. 2008's fit, normalized at 65504), the albedo clamped to [0, 1], the normal mapped from
/// [-1, 1] to [0, 1]; the image padded to a multiple of 16 with zeros; the network's five
/// levels (3x3 convolutions, ReLU, 2x2 max pooling, nearest upsampling, skip concatenation);
/// the output mapped back. TBB-parallel over output rows; every value a sum in a fixed order,
/// so the result is the same at any thread count.

#include "voxcone/denoise/tza.h"
#include "voxcone/image/image.h"

#include <map>
#include <memory>
#include <string>
#include <vector>

namespace voxcone {

/// Where the time of one denoise() went (seconds).
struct DenoiseTimings {
  double input = 0.0;    ///< the transfer function into the padded tensor (after the exposure)
  double network = 0.0;  ///< the convolutions, pooling and upsampling
  double output = 0.0;   ///< the inverse transfer, cropping
};

class Denoiser {
public:
  /// The weight file for the auxiliary images given: rt_hdr.tza (colour only),
  /// rt_hdr_alb.tza (with albedo), rt_hdr_alb_nrm.tza (with albedo and normal). A normal
  /// without an albedo is a SettingsError (OIDN has no such filter).
  static std::string weightsFile(bool albedo, bool normal);
  /// The network of `weights` (a .tza's tensors: enc_conv0 .. dec_conv0), taking
  /// `inputChannels` (3, 6 or 9: colour, albedo, normal); a missing tensor or one of the wrong
  /// shape is an ImageError.
  Denoiser(const std::map<std::string, TzaTensor>& weights, int inputChannels);
  ~Denoiser();
  Denoiser(Denoiser&&) noexcept;
  Denoiser& operator=(Denoiser&&) noexcept;

  int inputChannels() const { return m_inputChannels; }
  /// The convolution kernels this CPU runs ("avx2" where it has AVX2 and FMA, "generic"), the
  /// fastest first; a new Denoiser uses the first.
  static std::vector<std::string> kernels();
  /// Use kernel `name` (one of kernels(); else a SettingsError): the tests run each.
  void setKernel(const std::string& name);
  const std::string& kernel() const { return m_kernel; }
  /// The denoised colour. `albedo` and `normal` are given exactly where the network takes them
  /// (inputChannels 6: albedo; 9: both), of the colour's size. Non-finite inputs count as 0.
  Image denoise(const Image& color, const Image* albedo = nullptr, const Image* normal = nullptr,
                DenoiseTimings* timings = nullptr) const;
  /// Bytes of the network's tensors for a width x height image (one tile's window when tiled).
  size_t memoryBytes(int width, int height) const;
  /// Images whose tensors would exceed kMaxMemory are denoised in square tiles, each run on a
  /// window kTileOverlap pixels wider all round (more than the network's receptive radius,
  /// about 110 pixels by its layers), so that the image is the same as without tiles.
  /// 1.5 GiB: 1024 x 1024 (1.24 GB of tensors) runs whole, a 4K frame in tiles (whole it would
  /// take 8 GB), on the 24 GB machines this runs on. (At 1 GiB 1024 x 1024 was tiled: 3.0 s of
  /// network against 1.6 s whole.)
  static constexpr size_t kMaxMemory = size_t(3) << 29;
  static constexpr int kTileOverlap = 128;
  /// Tiles of `tile` pixels (a multiple of 16; 0: as kMaxMemory decides): the tests' way to tile
  /// a small image.
  void setTiling(int tile);
  /// The autoexposure scale OIDN applies to `color` before the transfer function.
  static float autoexposure(const Image& color);
  /// The PU transfer function (normalized: 65504 maps to 1) and its inverse.
  static float puForward(float y);
  static float puInverse(float x);

  struct Layer;  ///< one convolution's repacked weights (denoiser.cpp)
  struct Plan;   ///< the tensors of one run (denoiser.cpp)

private:
  /// The network on the whole of `color` (a tile's window) with exposure `scale`, into `result`.
  void run(const Image& color, const Image* albedo, const Image* normal, float scale, Image& result,
           DenoiseTimings* timings) const;

  int m_inputChannels = 0;
  std::string m_kernel;
  int m_tile = 0;
  std::vector<std::unique_ptr<Layer>> m_layers;
};

}  // namespace voxcone
