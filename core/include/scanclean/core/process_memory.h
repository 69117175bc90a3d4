#pragma once
//! \file process_memory.h
//! How a scanclean program's allocator treats the large arrays the filter frees between its
//! phases. By default glibc gives every block above its mmap threshold (128 KiB at first, then
//! raised to the largest such block freed) its own mapping, returns it to the kernel when it is
//! freed, and trims the top of its heap above twice that threshold. Each phase's arrays are then
//! fresh memory, and every page of them a fault: a trap into the kernel that costs microseconds
//! in a virtual machine. keep_freed_arrays_for_reuse() raises both thresholds once, before any
//! work, so that blocks of up to 32 MiB (glibc's largest mmap threshold) come from the heap, and
//! freed memory stays there, already faulted in, for the next phase: a 1M-point run takes about
//! 19,000 page faults instead of 27,000 (docs/HISTORY.md, "Stop 43"). Memory the
//! program freed is then not returned to the system until the program ends, up to
//! kKeptFreeBytes at the heap's top, and the peak grows a little where reused holes fit less
//! tightly than fresh mappings (+1.9 MiB at 1M points, +7.2 MiB at 2.1M). The programs
//! (scanclean, scanclean-mpi, scanclean_bench) call it first thing; the library never does,
//! since the setting belongs to the whole process.

#include <cstddef>

namespace scanclean {

//! Freed memory above this at the top of a heap is returned to the system.
constexpr std::size_t kKeptFreeBytes = std::size_t{1} << 30;
//! Blocks up to this size come from the heap (glibc accepts at most 32 MiB on 64-bit targets).
constexpr std::size_t kHeapBlockMaxBytes = std::size_t{32} << 20;

//! Sets the two thresholds (glibc's mallopt M_MMAP_THRESHOLD and M_TRIM_THRESHOLD). Returns
//! whether the allocator accepted both; false where the allocator is not glibc's or is
//! replaced (AddressSanitizer builds), and nothing changes. The values computed are the same
//! either way.
bool keep_freed_arrays_for_reuse() noexcept;

//! The process's peak resident memory so far, in bytes (VmHWM of /proc/self/status); 0 where
//! the system does not report it.
std::size_t peak_resident_bytes();

}  // namespace scanclean
