#pragma once
/// \file hash.h
/// Content hashes of input files for sidecars: XXH3's 128-bit hash (xxHash 0.8, Debian's
/// libxxhash), written as `xxhsum -H2 FILE` prints it, so that anyone can check a recorded
/// scene or mesh against the file they have. Not cryptographic: it names contents, it does not
/// defend against forgery. At about 20 GB/s a 30 MB mesh costs under 2 ms of a render.

#include <cstddef>
#include <cstdint>
#include <string>

namespace voxcone {

/// XXH3-128 of `size` bytes, as 32 lower-case hex digits (high 64 bits first).
std::string xxh128Hex(const void* data, size_t size);

/// XXH3-128 of a file's bytes, as xxh128Hex; `bytes` receives its size. Throws Error naming the
/// file when it cannot be read.
std::string fileXxh128(const std::string& path, uint64_t* bytes = nullptr);

}  // namespace voxcone
