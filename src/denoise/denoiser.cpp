#include "voxcone/denoise/denoiser.h"

#include "conv_kernel.h"
#include "voxcone/core/error.h"
#include "voxcone/core/timer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <new>

#include <sys/mman.h>

namespace voxcone {

using denoise::kBlock;
using denoise::TensorView;

namespace {

int blocksFor(int channels) { return (channels + kBlock - 1) / kBlock; }

/// The network's layers in order of evaluation (OIDN's UNet: encoder, bottleneck, decoder).
enum LayerId {
  kEnc0, kEnc1, kEnc2, kEnc3, kEnc4, kEnc5a, kEnc5b,
  kDec4a, kDec4b, kDec3a, kDec3b, kDec2a, kDec2b, kDec1a, kDec1b, kDec0, kLayerCount
};
const char* const kLayerNames[kLayerCount] = {
    "enc_conv0",  "enc_conv1",  "enc_conv2",  "enc_conv3",  "enc_conv4",  "enc_conv5a", "enc_conv5b", "dec_conv4a",
    "dec_conv4b", "dec_conv3a", "dec_conv3b", "dec_conv2a", "dec_conv2b", "dec_conv1a", "dec_conv1b", "dec_conv0"};

// The PU transfer function's fit (Aydin et al. 2008, "Extending Quality Metrics to Full
// Luminance Range Images", PU2 normalized at 100 cd/m^2), as OIDN's HDR filters use it.
constexpr float kPuA = 1.41283765e+03f, kPuB = 1.64593172e+00f, kPuC = 4.31384981e-01f, kPuD = -2.94139609e-03f;
constexpr float kPuE = 1.92653254e-01f, kPuF = 6.26026094e-03f, kPuG = 9.98620152e-01f;
constexpr float kPuY0 = 1.57945760e-06f, kPuY1 = 3.22087631e-02f, kPuX0 = 2.23151711e-03f, kPuX1 = 3.70974749e-01f;
constexpr float kHdrMax = 65504.0f;

float puRaw(float y) {
  if (y <= kPuY0) return kPuA * y;
  if (y <= kPuY1) return kPuB * std::pow(y, kPuC) + kPuD;
  return kPuE * std::log(y + kPuF) + kPuG;
}
float puRawInverse(float x) {
  if (x <= kPuX0) return x / kPuA;
  if (x <= kPuX1) return std::pow((x - kPuD) / kPuB, 1.0f / kPuC);
  return std::exp((x - kPuG) / kPuE) - kPuF;
}
const float kPuNorm = 1.0f / puRaw(kHdrMax);

float sanitize(float v, float lo, float hi) { return std::isnan(v) ? 0.0f : std::clamp(v, lo, hi); }

/// The network's memory: one anonymous mapping, zero as the kernel gives it (the tensors' zero
/// borders and padding need no clearing) and marked for transparent huge pages. perf showed
/// 35% of a 256x256 denoise in zeroing vectors and their page faults.
class Arena {
public:
  explicit Arena(size_t bytes) {
    m_bytes = (bytes + kHuge - 1) / kHuge * kHuge + kHuge;
    void* p = mmap(nullptr, m_bytes, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (p == MAP_FAILED) throw std::bad_alloc();
    m_map = static_cast<char*>(p);
    m_next = m_map + (kHuge - reinterpret_cast<uintptr_t>(m_map) % kHuge) % kHuge;
#ifdef MADV_HUGEPAGE
    madvise(m_next, m_bytes - size_t(m_next - m_map), MADV_HUGEPAGE);  // a hint
#endif
  }
  ~Arena() { munmap(m_map, m_bytes); }
  Arena(const Arena&) = delete;
  Arena& operator=(const Arena&) = delete;
  float* take(size_t floats) {
    float* p = reinterpret_cast<float*>(m_next);
    m_next += (floats * sizeof(float) + 63) / 64 * 64;
    return p;
  }

private:
  static constexpr size_t kHuge = size_t(2) << 20;
  char* m_map = nullptr;
  char* m_next = nullptr;
  size_t m_bytes = 0;
};

/// A channel-blocked tensor of one level with a zero border (TensorView's layout).
struct Buffer {
  float* data = nullptr;
  int blocks = 0, h = 0, w = 0;
  Buffer(int blocks_, int h_, int w_) : blocks(blocks_), h(h_), w(w_) {}
  size_t floats() const { return size_t(blocks) * size_t(h + 2) * size_t(w + 2) * kBlock; }
  /// Blocks [first, first + count).
  TensorView view(int first, int count) const {
    TensorView v;
    v.blockStride = size_t(h + 2) * size_t(w + 2) * kBlock;
    v.data = data + size_t(first) * v.blockStride;
    v.blocks = count;
    v.h = h;
    v.w = w;
    return v;
  }
  TensorView all() const { return view(0, blocks); }
};

denoise::ConvRowFn kernelByName(const std::string& name) {
#if defined(__x86_64__) && defined(VOXCONE_DENOISE_AVX2)
  if (name == "avx2") return denoise::avx2::convRow;
#endif
  return name == "generic" ? denoise::generic::convRow : nullptr;
}

void pool(const TensorView& in, const TensorView& out) {
  tbb::parallel_for(tbb::blocked_range<int>(0, out.blocks * out.h), [&](const tbb::blocked_range<int>& r) {
    for (int t = r.begin(); t != r.end(); ++t) {
      const int b = t / out.h, y = t % out.h;
      for (int x = 0; x < out.w; ++x) {
        float* o = out.pixel(b, y, x);
        const float* a = in.pixel(b, 2 * y, 2 * x);
        const float* c = in.pixel(b, 2 * y + 1, 2 * x);
        for (int k = 0; k < kBlock; ++k)
          o[k] = std::max(std::max(a[k], a[k + kBlock]), std::max(c[k], c[k + kBlock]));
      }
    }
  });
}

void upsample(const TensorView& in, const TensorView& out) {
  tbb::parallel_for(tbb::blocked_range<int>(0, out.blocks * out.h), [&](const tbb::blocked_range<int>& r) {
    for (int t = r.begin(); t != r.end(); ++t) {
      const int b = t / out.h, y = t % out.h;
      for (int x = 0; x < out.w; ++x) std::copy_n(in.pixel(b, y / 2, x / 2), kBlock, out.pixel(b, y, x));
    }
  });
}

}  // namespace

/// One 3x3 convolution: weights repacked for conv_kernel.h ([ob][ib][ky][kx][i][o], the input's
/// channels as the padded blocks of its concatenated parts), bias padded to whole blocks.
struct Denoiser::Layer {
  int inBlocks = 0, outBlocks = 0;
  std::vector<float> weights, bias;
};

std::string Denoiser::weightsFile(bool albedo, bool normal) {
  if (normal && !albedo) throw SettingsError("denoise: a normal image needs an albedo image too");
  return normal ? "rt_hdr_alb_nrm.tza" : albedo ? "rt_hdr_alb.tza" : "rt_hdr.tza";
}

Denoiser::Denoiser(const std::map<std::string, TzaTensor>& weights, int inputChannels)
    : m_inputChannels(inputChannels), m_kernel(kernels().front()) {
  if (inputChannels != 3 && inputChannels != 6 && inputChannels != 9)
    throw SettingsError("denoise: the network takes 3, 6 or 9 input channels, not " + std::to_string(inputChannels));
  int out[kLayerCount] = {};
  for (int id = 0; id < kLayerCount; ++id) {
    const std::string name = kLayerNames[id];
    const auto w = weights.find(name + ".weight");
    const auto b = weights.find(name + ".bias");
    if (w == weights.end() || b == weights.end()) throw ImageError("denoiser weights: no tensor '" + name + "'");
    const TzaTensor& wt = w->second;
    if (wt.layout != "oihw" || wt.dims.size() != 4 || wt.dims[2] != 3 || wt.dims[3] != 3)
      throw ImageError("denoiser weights: '" + name + ".weight' is not a 3x3 convolution (oihw)");
    out[id] = wt.dims[0];
    if (wt.values.size() != wt.size() || b->second.values.size() != b->second.size())
      throw ImageError("denoiser weights: '" + name + "' holds fewer values than its dimensions");
    if (b->second.dims != std::vector<int>{out[id]})
      throw ImageError("denoiser weights: '" + name + ".bias' does not match its " + std::to_string(out[id]) + " outputs");
    // The input's parts: the previous layer, or the upsampled layer and the encoder's skip.
    std::vector<int> parts;
    switch (id) {
      case kEnc0: parts = {inputChannels}; break;
      case kDec4a: parts = {out[kEnc5b], out[kEnc3]}; break;
      case kDec3a: parts = {out[kDec4b], out[kEnc2]}; break;
      case kDec2a: parts = {out[kDec3b], out[kEnc1]}; break;
      case kDec1a: parts = {out[kDec2b], inputChannels}; break;
      default: parts = {out[id - 1]}; break;
    }
    int inChannels = 0;
    for (int p : parts) inChannels += p;
    if (wt.dims[1] != inChannels)
      throw ImageError("denoiser weights: '" + name + "' takes " + std::to_string(wt.dims[1]) + " channels, expected " +
                       std::to_string(inChannels) + " (a network for " + std::to_string(inputChannels) +
                       " input channels?)");
    auto layer = std::make_unique<Layer>();
    layer->outBlocks = blocksFor(out[id]);
    // Padded input channel -> the file's input channel (-1: a zero channel of padding).
    std::vector<int> source;
    int base = 0;
    for (int p : parts) {
      for (int c = 0; c < blocksFor(p) * kBlock; ++c) source.push_back(c < p ? base + c : -1);
      base += p;
    }
    layer->inBlocks = int(source.size()) / kBlock;
    layer->weights.assign(size_t(layer->outBlocks) * size_t(layer->inBlocks) * 9 * kBlock * kBlock, 0.0f);
    for (int o = 0; o < out[id]; ++o)
      for (size_t pi = 0; pi < source.size(); ++pi) {
        if (source[pi] < 0) continue;
        for (int ky = 0; ky < 3; ++ky)
          for (int kx = 0; kx < 3; ++kx) {
            const float v = wt.values[((size_t(o) * size_t(inChannels) + size_t(source[pi])) * 3 + size_t(ky)) * 3 + size_t(kx)];
            const size_t ob = size_t(o / kBlock), ib = pi / kBlock;
            const size_t at = ((((ob * size_t(layer->inBlocks) + ib) * 3 + size_t(ky)) * 3 + size_t(kx)) * kBlock +
                               pi % kBlock) * kBlock + size_t(o % kBlock);
            layer->weights[at] = v;
          }
      }
    layer->bias.assign(size_t(layer->outBlocks) * kBlock, 0.0f);
    std::copy(b->second.values.begin(), b->second.values.end(), layer->bias.begin());
    m_layers.push_back(std::move(layer));
  }
  if (out[kDec0] != 3) throw ImageError("denoiser weights: dec_conv0 gives " + std::to_string(out[kDec0]) + " channels, not 3");
}

std::vector<std::string> Denoiser::kernels() {
  std::vector<std::string> out;
#if defined(__x86_64__) && defined(VOXCONE_DENOISE_AVX2)
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) out.push_back("avx2");
#endif
  out.push_back("generic");
  return out;
}

void Denoiser::setKernel(const std::string& name) {
  const std::vector<std::string> k = kernels();
  if (std::find(k.begin(), k.end(), name) == k.end()) throw SettingsError("denoise: no kernel '" + name + "' on this CPU");
  m_kernel = name;
}

Denoiser::~Denoiser() = default;
Denoiser::Denoiser(Denoiser&&) noexcept = default;
Denoiser& Denoiser::operator=(Denoiser&&) noexcept = default;

float Denoiser::puForward(float y) { return puRaw(y) * kPuNorm; }
float Denoiser::puInverse(float x) { return puRawInverse(x / kPuNorm); }

float Denoiser::autoexposure(const Image& color) {
  constexpr int kBin = 16;
  constexpr float kKey = 0.18f, kEps = 1e-8f;
  const int H = color.height, W = color.width;
  const int binsH = (H + kBin - 1) / kBin, binsW = (W + kBin - 1) / kBin;
  double logSum = 0.0;
  int count = 0;
  for (int i = 0; i < binsH; ++i)
    for (int j = 0; j < binsW; ++j) {
      const int y0 = int(int64_t(i) * H / binsH), y1 = int(int64_t(i + 1) * H / binsH);
      const int x0 = int(int64_t(j) * W / binsW), x1 = int(int64_t(j + 1) * W / binsW);
      double L = 0.0;
      for (int y = y0; y < y1; ++y)
        for (int x = x0; x < x1; ++x) {
          const Vec3& c = color.at(x, y);
          const float m = std::numeric_limits<float>::max();
          L += 0.212671 * sanitize(c.x, 0.0f, m) + 0.715160 * sanitize(c.y, 0.0f, m) + 0.072169 * sanitize(c.z, 0.0f, m);
        }
      L /= double((y1 - y0) * (x1 - x0));
      if (L > kEps) {
        logSum += std::log2(L);
        ++count;
      }
    }
  return count > 0 ? float(kKey / std::exp2(logSum / count)) : 1.0f;
}

/// The network's tensors for one padded H0 x W0 image (Buffer's layout): the decoder's
/// concatenations hold the encoder's skips as their last blocks, written there by the pooling,
/// so a concatenation costs nothing. Their memory is one Arena.
struct Denoiser::Plan {
  Buffer cat1, a0, b0, out0, cat2, e2, d2a, d2b, cat3, e3, d3a, d3b, cat4, e4, d4a, d4b, p4, e5a, e5b;
  Plan(const std::vector<std::unique_ptr<Layer>>& L, int inBlocks, int H0, int W0)
      : cat1(L[kDec2b]->outBlocks + inBlocks, H0, W0),
        a0(std::max(L[kEnc0]->outBlocks, L[kDec1a]->outBlocks), H0, W0),
        b0(std::max(L[kEnc1]->outBlocks, L[kDec1b]->outBlocks), H0, W0),
        out0(L[kDec0]->outBlocks, H0, W0),
        cat2(L[kDec3b]->outBlocks + L[kEnc1]->outBlocks, H0 / 2, W0 / 2),
        e2(L[kEnc2]->outBlocks, H0 / 2, W0 / 2),
        d2a(L[kDec2a]->outBlocks, H0 / 2, W0 / 2),
        d2b(L[kDec2b]->outBlocks, H0 / 2, W0 / 2),
        cat3(L[kDec4b]->outBlocks + L[kEnc2]->outBlocks, H0 / 4, W0 / 4),
        e3(L[kEnc3]->outBlocks, H0 / 4, W0 / 4),
        d3a(L[kDec3a]->outBlocks, H0 / 4, W0 / 4),
        d3b(L[kDec3b]->outBlocks, H0 / 4, W0 / 4),
        cat4(L[kEnc5b]->outBlocks + L[kEnc3]->outBlocks, H0 / 8, W0 / 8),
        e4(L[kEnc4]->outBlocks, H0 / 8, W0 / 8),
        d4a(L[kDec4a]->outBlocks, H0 / 8, W0 / 8),
        d4b(L[kDec4b]->outBlocks, H0 / 8, W0 / 8),
        p4(L[kEnc4]->outBlocks, H0 / 16, W0 / 16),
        e5a(L[kEnc5a]->outBlocks, H0 / 16, W0 / 16),
        e5b(L[kEnc5b]->outBlocks, H0 / 16, W0 / 16) {}
  std::vector<Buffer*> buffers() {
    return {&cat1, &a0, &b0, &out0, &cat2, &e2, &d2a, &d2b, &cat3, &e3, &d3a, &d3b, &cat4, &e4, &d4a, &d4b, &p4, &e5a, &e5b};
  }
  size_t bytes() {
    size_t floats = 0;
    for (const Buffer* b : buffers()) floats += (b->floats() + 15) / 16 * 16;
    return floats * sizeof(float);
  }
};

size_t Denoiser::memoryBytes(int width, int height) const {
  return Plan(m_layers, blocksFor(m_inputChannels), (height + 15) / 16 * 16, (width + 15) / 16 * 16).bytes();
}

void Denoiser::setTiling(int tile) {
  if (tile < 0 || tile % 16 != 0) throw SettingsError("denoise: a tile is a multiple of 16 pixels");
  m_tile = tile;
}

Image Denoiser::denoise(const Image& color, const Image* albedo, const Image* normal, DenoiseTimings* timings) const {
  const bool wantAlbedo = m_inputChannels >= 6, wantNormal = m_inputChannels == 9;
  if (wantAlbedo != (albedo != nullptr) || wantNormal != (normal != nullptr))
    throw SettingsError("denoise: this network takes " + std::string(wantNormal ? "an albedo and a normal image" : wantAlbedo ? "an albedo image" : "the colour alone"));
  for (const Image* aux : {albedo, normal})
    if (aux && (aux->width != color.width || aux->height != color.height))
      throw SettingsError("denoise: the auxiliary images must be the colour's size");
  const int H = color.height, W = color.width;
  Image result(W, H);
  if (H == 0 || W == 0) return result;
  if (timings) *timings = DenoiseTimings();
  // The exposure is the whole image's, whatever the tiles.
  const float scale = autoexposure(color);
  // Tiles: the whole image where its tensors fit kMaxMemory, else the largest square tile (a
  // multiple of 16) whose window (the tile and kTileOverlap all round) does.
  int tile = m_tile;
  if (tile == 0 && memoryBytes(W, H) > kMaxMemory) {
    tile = 256;
    while (memoryBytes(tile + 16 + 2 * kTileOverlap, tile + 16 + 2 * kTileOverlap) <= kMaxMemory) tile += 16;
  }
  if (tile == 0 || (tile >= W && tile >= H)) {
    run(color, albedo, normal, scale, result, timings);
    return result;
  }
  // Each tile's window starts at a multiple of 16 and reaches kTileOverlap beyond the tile (the
  // network's receptive radius is under it): its pooling grid is the whole image's, and every
  // value the tile keeps is computed from the same inputs in the same order as without tiles.
  const auto crop = [](const Image* img, int x0, int y0, int w, int h) {
    Image out(w, h);
    if (img)
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) out.at(x, y) = img->at(x0 + x, y0 + y);
    return out;
  };
  for (int ty = 0; ty < H; ty += tile)
    for (int tx = 0; tx < W; tx += tile) {
      const int x0 = std::max(0, tx - kTileOverlap), y0 = std::max(0, ty - kTileOverlap);
      const int x1 = std::min(W, tx + tile + kTileOverlap), y1 = std::min(H, ty + tile + kTileOverlap);
      const Image c = crop(&color, x0, y0, x1 - x0, y1 - y0);
      const Image a = crop(albedo, x0, y0, x1 - x0, y1 - y0), n = crop(normal, x0, y0, x1 - x0, y1 - y0);
      Image out(x1 - x0, y1 - y0);
      DenoiseTimings t;
      run(c, albedo ? &a : nullptr, normal ? &n : nullptr, scale, out, &t);
      if (timings) {
        timings->input += t.input;
        timings->network += t.network;
        timings->output += t.output;
      }
      for (int y = ty; y < std::min(H, ty + tile); ++y)
        for (int x = tx; x < std::min(W, tx + tile); ++x) result.at(x, y) = out.at(x - x0, y - y0);
    }
  return result;
}

void Denoiser::run(const Image& color, const Image* albedo, const Image* normal, float scale, Image& result,
                   DenoiseTimings* timings) const {
  const int H = color.height, W = color.width;
  Timer timer;
  const int H0 = (H + 15) / 16 * 16, W0 = (W + 15) / 16 * 16;
  const auto& L = m_layers;
  const int inBlocks = blocksFor(m_inputChannels);
  Plan plan(m_layers, inBlocks, H0, W0);
  Arena arena(plan.bytes());
  for (Buffer* b : plan.buffers()) b->data = arena.take(b->floats());
  Buffer &cat1 = plan.cat1, &a0 = plan.a0, &b0 = plan.b0, &out0 = plan.out0, &cat2 = plan.cat2, &e2 = plan.e2;
  Buffer &d2a = plan.d2a, &d2b = plan.d2b, &cat3 = plan.cat3, &e3 = plan.e3, &d3a = plan.d3a, &d3b = plan.d3b;
  Buffer &cat4 = plan.cat4, &e4 = plan.e4, &d4a = plan.d4a, &d4b = plan.d4b, &p4 = plan.p4, &e5a = plan.e5a,
         &e5b = plan.e5b;

  // The input: transformed colour, albedo, normal; zeros in the padding.
  const TensorView input = cat1.view(L[kDec2b]->outBlocks, inBlocks);
  tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& r) {
    const float hi = std::numeric_limits<float>::max();
    for (int y = r.begin(); y != r.end(); ++y)
      for (int x = 0; x < W; ++x) {
        float v[9] = {};
        const Vec3& c = color.at(x, y);
        for (int k = 0; k < 3; ++k) v[k] = puForward(sanitize(c[k] * scale, 0.0f, hi));
        if (albedo)
          for (int k = 0; k < 3; ++k) v[3 + k] = sanitize(albedo->at(x, y)[k], 0.0f, 1.0f);
        if (normal)
          for (int k = 0; k < 3; ++k) v[6 + k] = sanitize(normal->at(x, y)[k], -1.0f, 1.0f) * 0.5f + 0.5f;
        for (int k = 0; k < m_inputChannels; ++k) input.pixel(k / kBlock, y, x)[k % kBlock] = v[k];
      }
  });
  if (timings) timings->input = timer.seconds();
  timer = Timer();

  const denoise::ConvRowFn convRow = kernelByName(m_kernel);
  const auto conv = [&](LayerId id, const TensorView& in, const TensorView& out) {
    const Layer& layer = *L[id];
    const int pairs = (layer.outBlocks + 1) / 2;
    tbb::parallel_for(tbb::blocked_range<int>(0, pairs * out.h), [&](const tbb::blocked_range<int>& r) {
      for (int t = r.begin(); t != r.end(); ++t)
        convRow(in, out, layer.weights.data(), layer.bias.data(), 2 * (t / out.h), t % out.h);
    });
  };
  const auto view = [](const Buffer& b, int blocks) { return b.view(0, blocks); };
  const int skip1 = L[kDec3b]->outBlocks, skip2 = L[kDec4b]->outBlocks, skip3 = L[kEnc5b]->outBlocks;
  // Encoder.
  conv(kEnc0, input, view(a0, L[kEnc0]->outBlocks));
  conv(kEnc1, view(a0, L[kEnc0]->outBlocks), view(b0, L[kEnc1]->outBlocks));
  const TensorView pool1 = cat2.view(skip1, L[kEnc1]->outBlocks);
  pool(view(b0, L[kEnc1]->outBlocks), pool1);
  conv(kEnc2, pool1, e2.all());
  const TensorView pool2 = cat3.view(skip2, L[kEnc2]->outBlocks);
  pool(e2.all(), pool2);
  conv(kEnc3, pool2, e3.all());
  const TensorView pool3 = cat4.view(skip3, L[kEnc3]->outBlocks);
  pool(e3.all(), pool3);
  conv(kEnc4, pool3, e4.all());
  pool(e4.all(), p4.all());
  conv(kEnc5a, p4.all(), e5a.all());
  conv(kEnc5b, e5a.all(), e5b.all());
  // Decoder: upsample into the concatenation's first blocks, then convolve all of it.
  upsample(e5b.all(), cat4.view(0, skip3));
  conv(kDec4a, cat4.all(), d4a.all());
  conv(kDec4b, d4a.all(), d4b.all());
  upsample(d4b.all(), cat3.view(0, skip2));
  conv(kDec3a, cat3.all(), d3a.all());
  conv(kDec3b, d3a.all(), d3b.all());
  upsample(d3b.all(), cat2.view(0, skip1));
  conv(kDec2a, cat2.all(), d2a.all());
  conv(kDec2b, d2a.all(), d2b.all());
  upsample(d2b.all(), cat1.view(0, L[kDec2b]->outBlocks));
  conv(kDec1a, cat1.all(), view(a0, L[kDec1a]->outBlocks));
  conv(kDec1b, view(a0, L[kDec1a]->outBlocks), view(b0, L[kDec1b]->outBlocks));
  conv(kDec0, view(b0, L[kDec1b]->outBlocks), out0.all());
  if (timings) timings->network = timer.seconds();
  timer = Timer();

  const TensorView outView = out0.all();
  const float outputScale = scale != 0.0f ? 1.0f / scale : 0.0f;
  tbb::parallel_for(tbb::blocked_range<int>(0, H), [&](const tbb::blocked_range<int>& r) {
    const float hi = std::numeric_limits<float>::max();
    for (int y = r.begin(); y != r.end(); ++y)
      for (int x = 0; x < W; ++x) {
        const float* o = outView.pixel(0, y, x);
        for (int k = 0; k < 3; ++k) result.at(x, y)[k] = puInverse(sanitize(o[k], 0.0f, hi)) * outputScale;
      }
  });
  if (timings) timings->output = timer.seconds();
}

}  // namespace voxcone
