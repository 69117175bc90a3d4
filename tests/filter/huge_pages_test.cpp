// The huge-page requests of the filter's large arrays (filter/src/huge_pages.h): which ranges are
// advised, that the kernel records the request on the array's memory (the "hg" flag of its
// mapping in /proc/self/smaps), and that the helpers leave the vectors' contents as reserve,
// resize and assign do.

#include "../../filter/src/huge_pages.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

#include "../../filter/src/fill_later.h"

namespace scanclean::detail {
namespace {

constexpr std::uintptr_t kHuge = kHugePageSize;

// The kernel's transparent huge page setting ("always", "madvise" or "never"), or "" when the
// kernel has none.
std::string thp_setting() {
  std::ifstream f("/sys/kernel/mm/transparent_hugepage/enabled");
  std::string line;
  if (!std::getline(f, line)) return "";
  const auto b = line.find('['), e = line.find(']');
  return b == std::string::npos || e == std::string::npos ? "" : line.substr(b + 1, e - b - 1);
}

// The VmFlags of the mapping that holds address a, from /proc/self/smaps ("" if none does).
std::string vm_flags_at(std::uintptr_t a) {
  std::ifstream f("/proc/self/smaps");
  std::string line;
  bool inside = false;
  while (std::getline(f, line)) {
    const auto dash = line.find('-');
    const auto space = line.find(' ');
    if (dash != std::string::npos && space != std::string::npos && dash < space &&
        line.find(':') > space) {  // a mapping's first line: "begin-end perms ..."
      const std::uintptr_t begin = std::stoull(line.substr(0, dash), nullptr, 16);
      const std::uintptr_t end = std::stoull(line.substr(dash + 1, space - dash - 1), nullptr, 16);
      inside = begin <= a && a < end;
      continue;
    }
    if (inside && line.rfind("VmFlags:", 0) == 0) return line.substr(8) + " ";
  }
  return "";
}

bool advised(std::uintptr_t a) {
  return vm_flags_at(a).find(" hg ") != std::string::npos;
}

// The first 2 MiB boundary in v's storage.
template <class V>
std::uintptr_t first_boundary(const V& v) {
  return (reinterpret_cast<std::uintptr_t>(v.data()) + kHuge - 1) & ~(kHuge - 1);
}

TEST(HugePagesTest, SmallEmptyAndUnalignableRangesAreNotAdvised) {
  EXPECT_FALSE(advise_huge_pages(nullptr, std::size_t{64} << 20));
  std::vector<char> small(kHugePageAdviceMin - 1);
  EXPECT_FALSE(advise_huge_pages(small.data(), small.size()));
  // 2 MiB that start just past a boundary hold no whole aligned huge page.
  std::vector<char> big(3 * kHuge);
  const std::uintptr_t past = first_boundary(big) + 4096;
  EXPECT_FALSE(advise_huge_pages(reinterpret_cast<void*>(past), kHuge));
}

TEST(HugePagesTest, LargeArraysAskForHugePagesBeforeTheirFirstWrite) {
  const std::string thp = thp_setting();
  if (thp.empty() || thp == "never")
    GTEST_SKIP() << "this kernel has no transparent huge pages to ask for (setting: '" << thp
                 << "')";
  std::vector<float> v;
  reserve_huge(v, std::size_t{6} << 20);  // 24 MiB
  const std::uintptr_t a = first_boundary(v);
  ASSERT_TRUE(advised(a)) << "no MADV_HUGEPAGE on the reserved storage: " << vm_flags_at(a);
  // The part before the first boundary shares its pages with other memory: not advised. (Its
  // mapping is another one, split off by the request.)
  const auto begin = reinterpret_cast<std::uintptr_t>(v.data());
  if (begin < a) {
    EXPECT_FALSE(advised(begin)) << vm_flags_at(begin);
  }

  FillLaterVector<double> f(std::size_t{3} << 20);  // 24 MiB through the allocator
  EXPECT_TRUE(advised(first_boundary(f))) << vm_flags_at(first_boundary(f));
}

TEST(HugePagesTest, HelpersKeepTheVectorSemantics) {
  std::vector<std::uint32_t> v = {5, 6, 7};
  resize_huge(v, std::size_t{2} << 20);  // 8 MiB: reallocated, the first elements kept
  ASSERT_EQ(v.size(), std::size_t{2} << 20);
  EXPECT_EQ(v[0], 5u);
  EXPECT_EQ(v[1], 6u);
  EXPECT_EQ(v[2], 7u);
  EXPECT_EQ(v.back(), 0u);
  assign_huge(v, std::size_t{3} << 20, std::uint32_t{9});
  ASSERT_EQ(v.size(), std::size_t{3} << 20);
  EXPECT_EQ(v.front(), 9u);
  EXPECT_EQ(v[v.size() / 2], 9u);
  EXPECT_EQ(v.back(), 9u);
  const std::uint32_t* storage = v.data();
  reserve_huge(v, 10);  // within capacity: nothing moves
  EXPECT_EQ(v.data(), storage);
  assign_huge(v, 4, std::uint32_t{1});
  EXPECT_EQ(v, (std::vector<std::uint32_t>{1, 1, 1, 1}));
}

}  // namespace
}  // namespace scanclean::detail
