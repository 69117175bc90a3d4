#include "scanclean/pipeline/pipeline.h"

#include <tbb/flow_graph.h>
#include <tbb/global_control.h>
#include <tbb/info.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <exception>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "scanclean/core/errors.h"

namespace scanclean {
namespace {

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point t) {
  return std::chrono::duration<double>(Clock::now() - t).count();
}

std::size_t frame_bytes(const RangeFrame& f) {
  std::size_t b = sizeof(RangeFrame) + f.depth.data.size() * sizeof(std::uint16_t);
  if (f.points) b += f.points->data.size() * sizeof(Eigen::Vector3f);
  if (f.confidence) b += f.confidence->data.size() * sizeof(float);
  if (f.sensor_normals) b += f.sensor_normals->data.size() * sizeof(Eigen::Vector3f);
  return b;
}

// One window on its way through the stages.
struct Job {
  std::size_t seq = 0;  // submission order: windows reach on_window in it
  std::size_t window = 0;
  std::uint64_t first_frame = 0;
  std::vector<RangeFrame> frames;
  std::vector<Clock::time_point> arrival;  // per frame
  std::size_t bytes = 0;
  WindowInput input;
  WindowResult result;
};
using JobPtr = std::shared_ptr<Job>;

double percentile(std::vector<double>& v, double q) {
  if (v.empty()) return 0;
  const auto k = static_cast<std::size_t>(std::llround(q * static_cast<double>(v.size() - 1)));
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(k), v.end());
  return v[k];
}

}  // namespace

void validate(const PipelineOptions& o) {
  if (o.acquisition.max_frames != 0 && o.acquisition.max_frames <= o.first_frame)
    throw OptionError("pipeline: frame range " + std::to_string(o.first_frame) + ":" +
                      std::to_string(o.acquisition.max_frames) +
                      " is empty; give A:B with B > A (or B empty for 'to the end')");
  if (o.memory_budget_bytes == 0)
    throw OptionError("pipeline: option memory_budget_bytes = 0 is out of range; valid: > 0");
  validate(o.acquisition);
  validate(o.window);
}

PipelineStats run_pipeline(RangeSource& source, const PipelineOptions& options,
                           const std::function<void(WindowOutput&&)>& on_window,
                           bool already_open) {
  validate(options);
  const auto start = Clock::now();
  PipelineStats st;
  if (!already_open) source.open();
  st.info = source.info();
  const SourceInfo info = st.info;
  const WindowOptions& wopts = options.window;
  const bool may_skip = options.backlog == PipelineOptions::Backlog::kSkip ||
                        (options.backlog == PipelineOptions::Backlog::kAuto &&
                         (info.kind == "openni2" || info.kind == "vsensor"));

  // The stages run on TBB workers while this thread acquires: one worker more than the default
  // (whose one master slot this thread, busy reading the source, would not use).
  const int workers = std::max(1, tbb::info::default_concurrency());
  tbb::global_control parallelism(tbb::global_control::max_allowed_parallelism,
                                  static_cast<std::size_t>(workers) + 1);
  tbb::task_arena arena(workers + 1, 1);

  // Written only by the (serial) output stage; read after the graph is done.
  struct WindowCounts {
    std::size_t windows = 0, points_in = 0, points_out = 0, outliers = 0, points_fused = 0,
                fusion_rejected = 0, edge_dropped = 0, out_of_range = 0, no_normal = 0;
    std::size_t min_pf = 0, max_pf = 0;
    std::uint64_t frames_cleaned = 0;
    double seconds_points = 0, seconds_filter = 0;
    std::vector<double> latencies;
  } wc;
  std::atomic<std::size_t> waiting_bytes{0};
  std::size_t peak_waiting = 0;
  std::uint64_t frames_recorded = 0;

  // A serial node does not keep the order in which messages were put (a window put while
  // the node frees up can overtake one queued before it), so the output stage restores the
  // submission order: a window that arrives early waits for those before it.
  auto emit = [&](const JobPtr& j) {
    const WindowInput& in = j->input;  // moved-from cloud; the counts are intact
    wc.min_pf =
        wc.windows == 0 ? in.min_points_per_frame : std::min(wc.min_pf, in.min_points_per_frame);
    wc.max_pf = std::max(wc.max_pf, in.max_points_per_frame);
    ++wc.windows;
    wc.points_in += in.points_in;
    wc.points_fused += in.points_fused;
    wc.fusion_rejected += in.fusion_rejected;
    wc.edge_dropped += in.edge_dropped;
    wc.out_of_range += in.out_of_range;
    wc.no_normal += in.no_normal;
    wc.seconds_points += in.seconds_points;
    wc.seconds_filter += j->result.seconds_filter;
    wc.outliers += j->result.filter.removed();
    wc.points_out += j->result.cloud.size();
    wc.frames_cleaned += in.frames;
    WindowOutput out;
    out.window = j->window;
    out.first_frame = j->first_frame;
    out.frames = in.frames;
    out.last_frame = j->first_frame + in.frames - 1;
    out.cloud = std::move(j->result.cloud);
    out.outliers = std::move(j->result.outliers);
    out.filter = j->result.filter;
    out.input = std::move(j->result.input);
    if (on_window) on_window(std::move(out));
    const auto now = Clock::now();
    for (const auto& t : j->arrival)
      wc.latencies.push_back(std::chrono::duration<double>(now - t).count());
    waiting_bytes -= j->bytes;
  };
  std::map<std::size_t, JobPtr> early;  // output stage only: windows ahead of next_out
  std::size_t next_out = 0, next_seq = 0;
  std::unique_ptr<tbb::flow::graph> g;
  using Node = tbb::flow::function_node<JobPtr, JobPtr>;
  std::unique_ptr<Node> fuse_node, filter_node;
  std::unique_ptr<tbb::flow::function_node<JobPtr>> out_node;
  arena.execute([&] {
    g = std::make_unique<tbb::flow::graph>();
    fuse_node = std::make_unique<Node>(*g, tbb::flow::serial, [&](JobPtr j) {
      if (options.before_cleaning) options.before_cleaning(j->window);
      j->input = window_input(j->frames, info, wopts);
      j->frames = {};
      return j;
    });
    filter_node = std::make_unique<Node>(*g, tbb::flow::serial, [&](JobPtr j) {
      if (options.on_cleaning) options.on_cleaning(j->window, true);
      j->result = clean_window_input(std::move(j->input), wopts);
      if (options.on_cleaning) options.on_cleaning(j->window, false);
      return j;
    });
    out_node =
        std::make_unique<tbb::flow::function_node<JobPtr>>(*g, tbb::flow::serial, [&](JobPtr j) {
          early.emplace(j->seq, std::move(j));
          while (!early.empty() && early.begin()->first == next_out) {
            const JobPtr k = std::move(early.begin()->second);
            early.erase(early.begin());
            emit(k);
            ++next_out;
          }
          return tbb::flow::continue_msg();
        });
    tbb::flow::make_edge(*fuse_node, *filter_node);
    tbb::flow::make_edge(*filter_node, *out_node);
  });
  auto wait_all = [&] { arena.execute([&] { g->wait_for_all(); }); };

  JobPtr job;
  std::uint64_t first_index = 0, last_index = 0;
  std::size_t next_window = 0;
  // Hands the collected window on (or skips it); `last`: acquisition has ended.
  // A complete window beyond the budget is skipped only once the next frame arrives: the
  // window acquisition ends with is always cleaned.
  JobPtr skip_candidate;
  std::uint64_t candidate_first_index = 0, candidate_last_index = 0;
  auto confirm_skip = [&] {
    if (!skip_candidate) return;
    SkippedWindow s;
    s.window = skip_candidate->window;
    s.first_frame = skip_candidate->first_frame;
    s.last_frame = skip_candidate->first_frame + skip_candidate->frames.size() - 1;
    s.first_index = candidate_first_index;
    s.last_index = candidate_last_index;
    st.skipped.push_back(s);
    skip_candidate.reset();
  };
  auto submit = [&](JobPtr j, bool last) {
    const std::size_t waiting = waiting_bytes.load();
    if (waiting > 0 && waiting + j->bytes > options.memory_budget_bytes) {
      if (may_skip && !last) {
        skip_candidate = std::move(j);
        candidate_first_index = first_index;
        candidate_last_index = last_index;
        return;
      }
      wait_all();  // a file source (or the last window): wait for the backlog to be cleaned
    }
    j->seq = next_seq++;
    waiting_bytes += j->bytes;
    peak_waiting = std::max(peak_waiting, waiting_bytes.load());
    fuse_node->try_put(std::move(j));  // queued in the stages' arena
  };
  // Hands the collected window on (or skips it); `last`: acquisition has ended.
  auto flush = [&](bool last) {
    if (last && skip_candidate) submit(std::move(skip_candidate), true);
    if (!job || job->frames.empty()) return;
    JobPtr j = std::move(job);
    job.reset();
    submit(std::move(j), last);
  };

  AcquisitionOptions ao = options.acquisition;
  ao.keep_going = [&] {
    // A stage failed: stop, the error is rethrown below.
    if (g->is_cancelled()) return false;
    return !options.acquisition.keep_going || options.acquisition.keep_going();
  };
  try {
    static_cast<AcquisitionStats&>(st) =
        acquire(source, ao, [&](RangeFrame& frame, std::uint64_t pos) {
          if (options.record) {  // in this thread: the recording is part of acquisition
            options.record(info, frame);
            ++frames_recorded;
          }
          if (pos < options.first_frame) return;
          confirm_skip();  // acquisition goes on: the held window is skipped
          const auto now = Clock::now();
          if (!job) {
            job = std::make_shared<Job>();
            job->first_frame = pos;
            job->window =
                options.accumulate > 0
                    ? static_cast<std::size_t>((pos - options.first_frame) / options.accumulate)
                    : next_window;
            first_index = frame.index;
            if (options.accumulate > 0)
              job->frames.reserve(std::min<std::size_t>(options.accumulate, 1024));
          }
          last_index = frame.index;
          job->bytes += frame_bytes(frame);
          job->frames.push_back(std::move(frame));
          job->arrival.push_back(now);
          ++st.frames_used;
          if (options.on_frame) options.on_frame(st.frames_used);
          if (options.accumulate > 0 && job->frames.size() >= options.accumulate) {
            next_window = job->window + 1;
            flush(false);
          }
        });
    // Acquisition is over: a live device stops streaming (its frames would pile up in the
    // driver's queue while the backlog is cleaned).
    source.close();
    flush(true);  // the last (possibly partial) window: nothing read is lost
    wait_all();
  } catch (...) {
    const std::exception_ptr e = std::current_exception();
    g->cancel();
    try {
      wait_all();
    } catch (...) {  // the first error is the one reported
    }
    std::rethrow_exception(e);
  }

  st.windows = wc.windows;
  st.frames_cleaned = wc.frames_cleaned;
  st.points_in = wc.points_in;
  st.points_out = wc.points_out;
  st.outliers = wc.outliers;
  st.points_fused = wc.points_fused;
  st.fusion_rejected = wc.fusion_rejected;
  st.edge_dropped = wc.edge_dropped;
  st.out_of_range = wc.out_of_range;
  st.no_normal = wc.no_normal;
  st.min_points_per_frame = wc.min_pf;
  st.max_points_per_frame = wc.max_pf;
  st.seconds_points = wc.seconds_points;
  st.seconds_filter = wc.seconds_filter;
  st.latency_p50_s = percentile(wc.latencies, 0.5);
  st.latency_p95_s = percentile(wc.latencies, 0.95);
  st.peak_waiting_bytes = peak_waiting;
  st.frames_recorded = frames_recorded;
  st.seconds_total = seconds_since(start);
  return st;
}

}  // namespace scanclean
