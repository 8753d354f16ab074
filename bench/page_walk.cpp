// What a TLB miss costs on this machine, next to a cache miss: a chain of dependent loads over
// a buffer the size of a large HBVH (460 MiB, in huge pages where the kernel grants them), the
// next line picked at random (a) anywhere, (b) eight times in a row within one 2 MiB region, (c)
// eight times within one 4 KiB page. Where the host maps the guest's memory in 4 KiB pages, (b)
// costs what (a) does and (c) much less: every new 4 KiB page is a page walk, whatever the
// guest's page size. This is what the HBVH's block layout (hbvh.h, m_blocks) answers.
//   ./build-bench/bench/page_walk [MiB]

#include <sys/mman.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

namespace {

/// Nanoseconds a load, chasing `hops` lines in groups of `group` within regions of `region`
/// bytes of buf.
double chase(char* buf, size_t bytes, size_t region, int group, size_t hops) {
  const size_t linesPerRegion = region / 64, regions = bytes / region;
  std::mt19937_64 rng(1);
  std::vector<uint32_t> order(linesPerRegion), used(regions, 0);
  for (size_t i = 0; i < linesPerRegion; ++i) order[i] = uint32_t(i);
  std::shuffle(order.begin(), order.end(), rng);
  std::vector<size_t> seq;  // each line at most once: the chain is one cycle through all of them
  seq.reserve(hops);
  while (seq.size() < hops) {
    const size_t r = rng() % regions;
    if (used[r] + group > linesPerRegion) continue;
    for (int g = 0; g < group; ++g) seq.push_back(r * linesPerRegion + order[(used[r]++ + r) % linesPerRegion]);
  }
  for (size_t i = 0; i < seq.size(); ++i)
    *reinterpret_cast<char**>(buf + seq[i] * 64) = buf + seq[(i + 1) % seq.size()] * 64;
  char* p = buf + seq[0] * 64;
  const auto t0 = std::chrono::steady_clock::now();
  for (size_t i = 0; i < hops; ++i) p = *reinterpret_cast<char**>(p);
  const double ns = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0).count();
  if (p == nullptr) std::puts("");  // keeps the chain
  return ns / double(hops);
}

}  // namespace

int main(int argc, char** argv) {
  const size_t mib = argc > 1 ? std::strtoul(argv[1], nullptr, 10) : 460;
  if (mib < 64 || mib > 65536) {
    std::fprintf(stderr, "page_walk: buffer size must be 64..65536 MiB\n");
    return 2;
  }
  const size_t bytes = mib << 20;
  char* buf = static_cast<char*>(std::aligned_alloc(size_t(2) << 20, bytes));
  if (!buf) {
    std::fprintf(stderr, "page_walk: cannot allocate %zu MiB\n", mib);
    return 1;
  }
  madvise(buf, bytes, MADV_HUGEPAGE);
  for (size_t i = 0; i < bytes; i += 4096) buf[i] = 1;
  const size_t hops = 4000000;
  std::printf("dependent loads over %zu MiB, ns a load (median of 3)\n", mib);
  const struct {
    const char* name;
    size_t region;
    int group;
  } cases[] = {{"anywhere", 64, 1},
               {"8 in a row within 2 MiB", size_t(2) << 20, 8},
               {"8 in a row within 4 KiB", 4096, 8}};
  for (const auto& c : cases) {
    double t[3];
    for (double& x : t) x = chase(buf, bytes, c.region, c.group, hops);
    std::sort(t, t + 3);
    std::printf("  %-26s %7.1f\n", c.name, t[1]);
  }
  std::free(buf);
  return 0;
}
