#include "scanclean/core/process_memory.h"

#include <gtest/gtest.h>
#include <sys/resource.h>

#include <cstddef>
#include <cstdint>
#include <memory>

namespace {

long minor_faults() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_minflt;
}

// Writes one byte to every 4 KiB page of an array of `bytes`, then frees it.
void touch_and_free(std::size_t bytes) {
  std::unique_ptr<volatile std::uint8_t[]> a(new volatile std::uint8_t[bytes]);
  for (std::size_t i = 0; i < bytes; i += 4096) a[i] = 1;
}

}  // namespace

// An array freed between two phases is reused, already faulted in, by the next phase's array
// of the same size. Without the setting glibc returns the 16 MiB block to the kernel at once,
// and the second array faults in all its 4,096 pages again.
TEST(ProcessMemory, AFreedArrayIsReusedWithoutNewPageFaults) {
  if (!scanclean::keep_freed_arrays_for_reuse())
    GTEST_SKIP() << "the allocator is not glibc's, or is replaced (sanitizer build)";
  constexpr std::size_t kBytes = std::size_t{16} << 20;
  static_assert(kBytes < scanclean::kHeapBlockMaxBytes);
  touch_and_free(kBytes);  // the heap grows to hold it, and keeps it
  const long before = minor_faults();
  touch_and_free(kBytes);
  const long faults = minor_faults() - before;
  EXPECT_LT(faults, 64) << "pages faulted in again: " << faults << " of " << kBytes / 4096;
}

// The peak resident memory covers an array the process has written, and never falls.
TEST(ProcessMemory, ThePeakCoversAWrittenArrayAndNeverFalls) {
  const std::size_t before = scanclean::peak_resident_bytes();
  ASSERT_GT(before, 0u) << "no VmHWM in /proc/self/status";
  constexpr std::size_t kBytes = std::size_t{48} << 20;
  {
    std::unique_ptr<volatile std::uint8_t[]> a(new volatile std::uint8_t[kBytes]);
    for (std::size_t i = 0; i < kBytes; i += 4096) a[i] = 1;
    EXPECT_GE(scanclean::peak_resident_bytes(), kBytes);
  }
  EXPECT_GE(scanclean::peak_resident_bytes(), before);
}
