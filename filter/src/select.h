#pragma once
//! Internal: exact selections of the k-th smallest value, faster than std::nth_element (by
//! counting for a few values, by bins when their range is known), the distance counts that feed
//! them (the adaptive scale's bands, the outlier tests' sums), and the selections of points by
//! distance (the candidate kernels, the cell caches). The loops over points are vectorised with
//! Google Highway for the processor the program runs on, in vectors of 8 floats (16 with
//! AVX-512 for the loops that mask their tails: the counts, bands and near-box copies); every
//! target rounds as a plain scalar loop does, so the results are the same on every processor.

#include <cstddef>
#include <cstdint>

namespace scanclean::detail {

//! The loops that append (count_below_and_band, select_near_box) may store a whole vector past
//! their last value (16 floats with AVX-512): their outputs need room for this many more.
constexpr std::size_t kStoreSlack = 16;

//! The k-th smallest (0-based rank) of v[0, n), k < n: the value std::nth_element would put at
//! v[k]. For n <= kSmallSelect by counting (for each value, how many lie below it and at or
//! below it; about twice as fast as std::nth_element at 36 values), else, or with a NaN among
//! the values, std::nth_element (which may reorder v).
constexpr std::size_t kSmallSelect = 64;
float kth_smallest_small(float* v, std::size_t n, std::size_t k);

//! The k-th smallest (0-based rank) of v[0, n), k < n, every value in [0, upper): the value
//! std::nth_element would put at v[k]. Sorts the values into 64 equal bins of [0, upper) (a
//! monotone map, so a bin's values lie between its neighbours'), then selects within the one bin
//! that holds rank k (kth_smallest_small). Overwrites v (scratch). kth_smallest_small alone for
//! n <= 64 or upper <= 0; values outside [0, upper) go to the end bins, which keeps the result
//! exact.
float kth_smallest_below(float* v, std::size_t n, std::size_t k, float upper);
//! As kth_smallest_below for values known to lie in [lower, upper): the bins split that range.
//! Values outside it go to the end bins, which keeps the result exact; kth_smallest_small alone
//! for n <= 64 or an empty or unrepresentable range.
float kth_smallest_between(float* v, std::size_t n, std::size_t k, float lower, float upper);

//! The squared distances d2_j = |p_j - q|^2 of the n points p_j = (x[j], y[j], z[j]), rounded
//! as (dx dx + dy dy) + dz dz in float: adds to `below` the number with d2_j < lo2, and appends
//! to band[m, ...) those with lo2 <= d2_j < hi2 (m grows by their number; band needs room for
//! m + n + kStoreSlack values).
//! With the count below a band that brackets rank k (below <= k < below + m), the k-th
//! smallest of all the d2 is the (k - below)-th smallest of the band.
void count_below_and_band(const float* x, const float* y, const float* z, std::size_t n,
                          const float q[3], float lo2, float hi2, std::size_t& below, float* band,
                          std::size_t& m);

//! Where select_near_box appends: coordinates, and the slot and extra values when the inputs
//! have them. Each needs room for m + n + kStoreSlack values.
struct NearBoxOut {
  float *x = nullptr, *y = nullptr, *z = nullptr;
  std::uint32_t* slot = nullptr;
  float* extra = nullptr;
};
//! Appends to out[m, ...) the points p_j = (x[j], y[j], z[j]), j < n, whose squared distance to
//! the box [lo, hi] (the sum of the squared gaps per axis, each rounded in float, without fused
//! multiply-add) is below r2, in order, with slot[j] and extra[j] when those are not null; m
//! grows by their number. A point's squared distance so rounded is at most its squared distance
//! to any q inside the box as count_below_and_band and select_within round it (float rounding
//! is monotone), so the points within r of such a q are all kept when r * r <= r2.
void select_near_box(const float* x, const float* y, const float* z, const std::uint32_t* slot,
                     const float* extra, std::size_t n, const float lo[3], const float hi[3],
                     float r2, NearBoxOut out, std::size_t& m);

//! The largest float v with ratio x double(v) <= l (in double), so that for every float v that
//! test holds exactly when v <= bound (it is monotone in v for ratio > 0). False, leaving bound
//! as it was, when ratio is not positive, l is negative or not finite, or l / ratio lies past
//! float's range.
bool largest_float_scaled_at_or_below(double ratio, double l, float& bound);

//! What count_within found among the points within r.
struct WithinCounts {
  std::uint64_t sum = 0;        //!< sum of their cnt values
  std::size_t n = 0;            //!< their number
  std::size_t at_or_below = 0;  //!< their number with lik <= lik_max (0 without lik)
};

//! Over the n points p_j = (x[j], y[j], z[j]) with d2_j = |p_j - q|^2 < r2, rounded as in
//! count_below_and_band: adds cnt[j] to out.sum, 1 to out.n, and 1 to out.at_or_below where
//! lik[j] <= lik_max (lik null: none). One pass, no list of the points: the density and
//! likelihood-ratio sums of the outlier tests. The cnt values of one call must sum below 2^32.
void count_within(const float* x, const float* y, const float* z, const std::uint32_t* cnt,
                  const float* lik, std::size_t n, const float q[3], float r2, float lik_max,
                  WithinCounts& out);

//! count_below_and_band, count_within and select_near_box as chosen for this processor, taken
//! once (select_loops) by callers that make many small calls, one per run of a cell's
//! neighbourhood: each call through the free functions pays the run-time dispatch (a call into
//! the Highway library), which cost the outlier tests of the 2.1M-point sphere about 5 %.
struct SelectLoops {
  void (*band)(const float* x, const float* y, const float* z, std::size_t n, const float* q,
               float lo2, float hi2, std::size_t* below, float* band, std::size_t* m) = nullptr;
  void (*within)(const float* x, const float* y, const float* z, const std::uint32_t* cnt,
                 const float* lik, std::size_t n, const float* q, float r2, float lik_max,
                 WithinCounts* out) = nullptr;
  void (*near_box)(const float* x, const float* y, const float* z, const std::uint32_t* slot,
                   const float* extra, std::size_t n, const float* lo, const float* hi, float r2,
                   NearBoxOut* out, std::size_t* m) = nullptr;

  void count_below_and_band(const float* x, const float* y, const float* z, std::size_t n,
                            const float q[3], float lo2, float hi2, std::size_t& below, float* out,
                            std::size_t& m) const {
    band(x, y, z, n, q, lo2, hi2, &below, out, &m);
  }
  void count_within(const float* x, const float* y, const float* z, const std::uint32_t* cnt,
                    const float* lik, std::size_t n, const float q[3], float r2, float lik_max,
                    WithinCounts& out) const {
    within(x, y, z, cnt, lik, n, q, r2, lik_max, &out);
  }
  void select_near_box(const float* x, const float* y, const float* z, const std::uint32_t* slot,
                       const float* extra, std::size_t n, const float lo[3], const float hi[3],
                       float r2, NearBoxOut out, std::size_t& m) const {
    near_box(x, y, z, slot, extra, n, lo, hi, r2, &out, &m);
  }
};
//! The loops for this processor (the run-time dispatch, once).
SelectLoops select_loops();

//! Writes to out, in order, the slots[j] of the points (x[j], y[j], z[j]), j < n, whose
//! squared distance to origin, (dx dx + dy dy) + dz dz in float without fused multiply-add (as
//! a plain scalar loop computes it), is below r2; returns their count. n a multiple of 8
//! (pad with +inf coordinates); out holds n entries (past the count it is scratch).
std::size_t select_within(const float* x, const float* y, const float* z,
                          const std::uint32_t* slots, std::size_t n, const float origin[3],
                          float r2, std::uint32_t* out);
//! As select_within, keeping only the points j that also lie within scale sigma[j] + margin of
//! origin: with reach = scale sigma[j] + margin in float, d2 < r2 and d2 < reach reach. For
//! kernel centres with sigma_j (KernelRecord::kSigma) and scale = the truncation: the kernels
//! that can reach a point within margin of origin.
std::size_t select_within_reach(const float* x, const float* y, const float* z, const float* sigma,
                                const std::uint32_t* slots, std::size_t n, const float origin[3],
                                float r2, float scale, float margin, std::uint32_t* out);
//! Copies the n points of xyz (x, y, z of each point in turn) into x, y and z, and the slots
//! first, first + 1, ... into slot: a run of an index's points as a struct of arrays.
void split_run(const float* xyz, std::size_t n, std::uint32_t first, float* x, float* y, float* z,
               std::uint32_t* slot);

}  // namespace scanclean::detail
