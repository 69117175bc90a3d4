#include "scanclean/core/process_memory.h"

#include <fstream>
#include <sstream>
#include <string>

#if defined(__GLIBC__)
#include <malloc.h>
#endif

// ASan's allocator replaces malloc, so glibc's settings would be ignored there.
#if defined(__SANITIZE_ADDRESS__)
#define SCANCLEAN_MALLOC_REPLACED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SCANCLEAN_MALLOC_REPLACED 1
#endif
#endif

namespace scanclean {

bool keep_freed_arrays_for_reuse() noexcept {
#if defined(__GLIBC__) && !defined(SCANCLEAN_MALLOC_REPLACED)
  // Both are needed: either one turns glibc's dynamic threshold off, and the mmap threshold
  // alone would still trim a freed array off the heap's top.
  const bool mmap_ok = mallopt(M_MMAP_THRESHOLD, static_cast<int>(kHeapBlockMaxBytes)) == 1;
  const bool trim_ok = mallopt(M_TRIM_THRESHOLD, static_cast<int>(kKeptFreeBytes)) == 1;
  return mmap_ok && trim_ok;
#else
  return false;
#endif
}

std::size_t peak_resident_bytes() {
  std::ifstream f("/proc/self/status");
  std::string line;
  while (std::getline(f, line)) {
    if (line.rfind("VmHWM:", 0) == 0) {
      std::istringstream s(line.substr(6));
      std::size_t kb = 0;
      s >> kb;
      return kb * 1024;
    }
  }
  return 0;
}

}  // namespace scanclean
