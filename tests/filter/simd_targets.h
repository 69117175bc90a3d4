#pragma once
// Runs a test body once for every instruction set the filter's Highway loops were compiled for
// that this processor has (AVX-512, AVX2, SSE4, ... and the portable fallback), with the
// dispatch forced to it, so that each target is checked against the oracle, not only the one
// the dispatch would choose here.

#include <gtest/gtest.h>
#include <hwy/targets.h>

namespace scanclean::test {

template <class F>
void for_each_simd_target(F&& body) {
  for (const std::int64_t target : hwy::SupportedAndGeneratedTargets()) {
    hwy::SetSupportedTargetsForTest(target);
    SCOPED_TRACE(hwy::TargetName(target));
    body();
  }
  hwy::SetSupportedTargetsForTest(0);  // the dispatch chooses again
}

}  // namespace scanclean::test
