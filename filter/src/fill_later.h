#pragma once
//! Internal: vectors whose elements are left uninitialised on resize, for large arrays that a
//! parallel loop fills right after. A std::vector<T>(n) of a trivial T is zeroed by the
//! allocating thread first: on a million points that is a serial pass over tens of megabytes
//! and every page's first fault taken by one thread. With this allocator the fill loop touches
//! each page first, in parallel, and writes it once.

#include <memory>
#include <new>
#include <type_traits>
#include <utility>
#include <vector>

#include "huge_pages.h"

namespace scanclean::detail {

template <class T>
struct FillLaterAllocator : std::allocator<T> {
  template <class U>
  struct rebind {
    using other = FillLaterAllocator<U>;
  };
  FillLaterAllocator() noexcept = default;
  template <class U>
  FillLaterAllocator(const FillLaterAllocator<U>&) noexcept {}  // NOLINT: rebinding
  //! Large arrays ask for huge pages before their first write (huge_pages.h).
  T* allocate(std::size_t n) {
    T* p = std::allocator<T>::allocate(n);
    advise_huge_pages(p, n * sizeof(T));
    return p;
  }
  //! Default-initialises: nothing is written for a trivial U.
  template <class U>
  void construct(U* p) noexcept(std::is_nothrow_default_constructible_v<U>) {
    ::new (static_cast<void*>(p)) U;
  }
  template <class U, class... Args>
  void construct(U* p, Args&&... args) {
    ::new (static_cast<void*>(p)) U(std::forward<Args>(args)...);
  }
};

//! A vector of T (trivial) that resize leaves unwritten: fill every element before reading it.
template <class T>
using FillLaterVector = std::vector<T, FillLaterAllocator<T>>;

}  // namespace scanclean::detail
