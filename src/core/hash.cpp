// XXH3-128 content hashes (hash.h), streamed in 1 MiB blocks.

#include "voxcone/core/hash.h"

#include "voxcone/core/error.h"

#include <xxhash.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>
#include <vector>

namespace voxcone {

namespace {

std::string toHex(XXH128_hash_t h) {
  char text[33];
  std::snprintf(text, sizeof text, "%016llx%016llx", static_cast<unsigned long long>(h.high64),
                static_cast<unsigned long long>(h.low64));
  return text;
}

}  // namespace

std::string xxh128Hex(const void* data, size_t size) { return toHex(XXH3_128bits(data, size)); }

std::string fileXxh128(const std::string& path, uint64_t* bytes) {
  std::unique_ptr<FILE, int (*)(FILE*)> f(std::fopen(path.c_str(), "rb"), &std::fclose);
  if (!f) throw Error(path + ": cannot read for its hash: " + std::strerror(errno));
  std::unique_ptr<XXH3_state_t, XXH_errorcode (*)(XXH3_state_t*)> state(XXH3_createState(), &XXH3_freeState);
  if (!state || XXH3_128bits_reset(state.get()) != XXH_OK) throw Error("xxHash: cannot start a hash");
  std::vector<unsigned char> block(size_t(1) << 20);
  uint64_t total = 0;
  for (;;) {
    const size_t n = std::fread(block.data(), 1, block.size(), f.get());
    if (n > 0) XXH3_128bits_update(state.get(), block.data(), n);
    total += n;
    if (n < block.size()) break;
  }
  if (std::ferror(f.get())) throw Error(path + ": read error while hashing");
  if (bytes) *bytes = total;
  return toHex(XXH3_128bits_digest(state.get()));
}

}  // namespace voxcone
