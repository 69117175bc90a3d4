#pragma once
//! Internal: the projection's inner loops over a point's candidate kernels, in float SIMD
//! (Google Highway, dispatched at run time: sums in 8 lanes on AVX2 and AVX-512, 4 on SSE4 and
//! NEON), with a fast exp. Candidates are held relative to a local origin (the point where they
//! were gathered) so float keeps full resolution. Per-lane partial sums are combined in double in a
//! fixed order, so results do not depend on threads (they may differ between 8-lane and 4-lane
//! targets, and with fused multiply-add or without).

#include <cstddef>
#include <cstdint>
#include <vector>

#include "kernel_record.h"

namespace scanclean::detail {

//! Struct of arrays, padded with inert entries to a multiple of kCandidatePadding.
constexpr std::size_t kCandidatePadding = 8;

//! One array of a CandidateBuffer (a field, or the distances): a view into the buffer's block.
class CandidateArray {
 public:
  float& operator[](std::size_t j) { return p_[j]; }
  float operator[](std::size_t j) const { return p_[j]; }
  float* data() { return p_; }
  const float* data() const { return p_; }

 private:
  friend struct CandidateBuffer;
  float* p_ = nullptr;
};

struct CandidateBuffer {
  static constexpr std::size_t kFields = 16;
  enum Field {
    kCx,
    kCy,
    kCz,  // centre minus local origin (metres)
    kQ00,
    kQ11,
    kQ22,  // S^-1 diagonal
    kQ01,
    kQ02,
    kQ12,  // 2 x S^-1 off-diagonal
    kNx,
    kNy,
    kNz,  // kernel normal (unoriented)
    kSlab2,
    kH2,
    kW,  // (slab h_j)^2, h_j^2, w_j
    kE   // scratch: masked Mahalanobis e_j
  };
  CandidateArray f[kFields];
  CandidateArray d;  // scratch: signed distances d_j
  std::size_t count = 0;
  std::size_t padded = 0;
  std::vector<unsigned> slot;  // kernel slot of each candidate

  CandidateBuffer() = default;
  CandidateBuffer(const CandidateBuffer&) = delete;  // the arrays point into its own block
  CandidateBuffer& operator=(const CandidateBuffer&) = delete;

  void clear() { count = 0; }
  void reserve(std::size_t n);  // capacity for n candidates (+ padding)
  //! Appends kernel `record` with its centre made relative to `origin`.
  void push_record(unsigned kernel_slot, const KernelRecord& record, const float origin[3],
                   float slab2) {
    const float* rec = record.f;
    if (count + kCandidatePadding >= capacity_) reserve(2 * count + 64);
    const std::size_t j = count++;
    f[kCx][j] = rec[0] - origin[0];
    f[kCy][j] = rec[1] - origin[1];
    f[kCz][j] = rec[2] - origin[2];
    for (std::size_t k = 3; k < 12; ++k) f[k][j] = rec[k];
    f[kSlab2][j] = slab2 * rec[12];
    f[kH2][j] = rec[12];
    f[kW][j] = rec[13];
    slot[j] = kernel_slot;
  }
  void finish();  // pads to a multiple of kCandidatePadding with inert entries

 private:
  std::vector<float> block_;  // the arrays f and d (reserve)
  std::size_t capacity_ = 0;  // entries of each array
};

// The record's fields are the buffer's, up to the normal (append_records copies them as they are).
constexpr bool same_field(std::size_t record_field, std::size_t buffer_field) {
  return record_field == buffer_field;
}
static_assert(same_field(KernelRecord::kCx, CandidateBuffer::kCx) &&
                  same_field(KernelRecord::kQ00, CandidateBuffer::kQ00) &&
                  same_field(KernelRecord::kQ12, CandidateBuffer::kQ12) &&
                  same_field(KernelRecord::kNz, CandidateBuffer::kNz),
              "KernelRecord and CandidateBuffer share the field order up to the normal");

struct StepSums {
  double s = 0;              // sum omega
  double dn[3] = {0, 0, 0};  // sum omega d n
  double n[3] = {0, 0, 0};   // sum omega n
  double slab_sum = 0;       // sum omega max(0, h2_j - d_j^2): L = exp(-e_min / 2) slab_sum
  float e_min = 0;
  //! L(x) at the x of these sums (likelihood() there, up to rounding) when every kernel that
  //! L keeps is also kept by the step, i.e. when the slab test is |d_j| < slab h_j with slab >= 1.
  double likelihood() const;
};

//! Appends the kernels records[slots[k]], k < n, with centres relative to origin; on x86, 8
//! records at a time by a transposition in registers (Highway, on AVX-512 and AVX2).
void append_records(CandidateBuffer& buffer, const KernelRecord* records,
                    const std::uint32_t* slots, std::size_t n, const float origin[3], float slab2);

//! One iteration's sums at x (relative to the local origin). Returns false if no kernel is kept
//! (e_j < t2 and d_j^2 < slab2_j). Fills buffer.f[kE] and buffer.d. The normal sum uses
//! s_j n_j with s_j = sign(n_j . nref); the likelihood's sum comes with them (StepSums).
bool step_sums(CandidateBuffer& buffer, const float x[3], const float nref[3], float t2,
               StepSums& out);
//! step_sums at the x of the min_mahalanobis call just before (no other call in between):
//! takes e_j and d_j from the buffer instead of computing them again; the same results, bit
//! for bit.
bool step_sums_after_min_mahalanobis(CandidateBuffer& buffer, const float nref[3], float t2,
                                     StepSums& out);
//! min e_j at x over the candidates that pass the slab test (d_j^2 < slab2_j); +inf if there is
//! none. Fills buffer.f[kE] with e_j (+inf where the slab test fails) and buffer.d with d_j.
float min_mahalanobis(CandidateBuffer& buffer, const float x[3]);
//! L(x) = sum w_j exp(-e_j / 2) max(0, h2_j - d_j^2) over kernels with e_j < t2.
double likelihood(CandidateBuffer& buffer, const float x[3], float t2);
//! The first candidate whose buffer.f[kE] is e (after min_mahalanobis: e_j, with +inf where the
//! slab test fails), or the last candidate if none is; 0 for an empty buffer. Needs finish().
std::size_t first_candidate_with_e(const CandidateBuffer& buffer, float e);
//! exp(a) for a in [-80, 0] with the same fast exp the loops use (relative error below 5e-7 on
//! [-10, 0], where the loops use it; up to 4e-6 towards -80, from rounding a log2(e) in float).
float fast_exp(float a);

}  // namespace scanclean::detail
