#pragma once
/// \file huge_pages.h
/// An allocator for large read-mostly arrays walked at random (the HBVH's nodes and triangle
/// packets): blocks of 2 MiB and more are 2 MiB aligned and marked for transparent huge pages
/// (madvise MADV_HUGEPAGE, as Embree's os_malloc does), so that a traversal touching a 50 MB tree
/// misses the TLB far less. Where the kernel gives no huge pages, the memory is ordinary.

#include <cstddef>
#include <cstdlib>
#include <new>

#include <sys/mman.h>

namespace voxcone {

template <class T>
struct HugePageAllocator {
  using value_type = T;
  static constexpr size_t kHugePage = size_t(2) << 20;  ///< bytes, x86-64's huge page

  HugePageAllocator() = default;
  template <class U>
  HugePageAllocator(const HugePageAllocator<U>&) {}

  T* allocate(size_t n) {
    const size_t bytes = n * sizeof(T);
    if (bytes < kHugePage) return static_cast<T*>(::operator new(bytes, std::align_val_t(alignof(T))));
    void* p = std::aligned_alloc(kHugePage, roundUp(bytes));
    if (!p) throw std::bad_alloc();
#ifdef MADV_HUGEPAGE
    madvise(p, roundUp(bytes), MADV_HUGEPAGE);  // a hint: failure leaves ordinary pages
#endif
    return static_cast<T*>(p);
  }
  void deallocate(T* p, size_t n) {
    if (n * sizeof(T) < kHugePage) ::operator delete(p, std::align_val_t(alignof(T)));
    else std::free(p);
  }
  template <class U>
  bool operator==(const HugePageAllocator<U>&) const { return true; }
  template <class U>
  bool operator!=(const HugePageAllocator<U>&) const { return false; }

private:
  static size_t roundUp(size_t bytes) { return (bytes + kHugePage - 1) / kHugePage * kHugePage; }
};

}  // namespace voxcone
