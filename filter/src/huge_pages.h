#pragma once
//! Internal: transparent huge pages for the filter's large arrays. A million-point run touches
//! some 200 MB of fresh memory; in 4 KiB pages that is about 50,000 page faults, each a trap
//! into the kernel (and, in a virtual machine, often out of it), and a third of them again for
//! arrays freed and allocated anew between the phases. Where the kernel hands out huge pages
//! only on request (transparent_hugepage "madvise", as on the machine the benchmark ran on at
//! stop 40), the filter asks for them on its large arrays before their first write: 2 MiB
//! pages, 512 times fewer faults. Where the setting is "always" this changes nothing; where it
//! is "never", or the kernel has no huge pages, the request is ignored. The values computed are
//! the same either way.

#include <cstddef>
#include <vector>

namespace scanclean::detail {

//! The size of a transparent huge page on x86-64 and most other Linux targets.
constexpr std::size_t kHugePageSize = std::size_t{2} << 20;
//! Arrays smaller than one huge page are left alone. Only the 2 MiB-aligned part of an array is
//! advised, so a huge page never holds another allocation's memory.
constexpr std::size_t kHugePageAdviceMin = kHugePageSize;

//! Asks for huge pages on the 2 MiB-aligned part of [p, p + bytes) when bytes is at least
//! kHugePageAdviceMin (madvise MADV_HUGEPAGE; Linux, else nothing). Returns whether the kernel
//! accepted the request; failures are not errors (the memory stays in normal pages).
bool advise_huge_pages(void* p, std::size_t bytes) noexcept;

//! v.reserve(n), with huge pages asked for before anything is written to the new storage.
template <class T, class A>
void reserve_huge(std::vector<T, A>& v, std::size_t n) {
  if (n <= v.capacity()) return;
  v.reserve(n);
  advise_huge_pages(v.data(), v.capacity() * sizeof(T));
}

//! v.resize(n) into storage that asked for huge pages first (see reserve_huge).
template <class T, class A>
void resize_huge(std::vector<T, A>& v, std::size_t n) {
  reserve_huge(v, n);
  v.resize(n);
}

//! v.assign(n, value) into storage that asked for huge pages first (see reserve_huge).
template <class T, class A>
void assign_huge(std::vector<T, A>& v, std::size_t n, const T& value) {
  reserve_huge(v, n);
  v.assign(n, value);
}

}  // namespace scanclean::detail
