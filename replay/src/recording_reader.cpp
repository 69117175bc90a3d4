#include "scanclean/replay/recording_reader.h"

#include <charconv>
#include <stdexcept>
#include <string_view>
#include <system_error>

#include "png16.h"
#include "scanclean/core/errors.h"

namespace scanclean {

namespace {

constexpr std::uintmax_t kMaxCsvBytes = std::uintmax_t{1} << 30;  // ~10 million frames

template <class T>
bool parse_int(std::string_view s, T& out) {
  if (s.empty()) return false;
  const char* end = s.data() + s.size();
  auto [p, ec] = std::from_chars(s.data(), end, out);
  return ec == std::errc() && p == end;
}

std::vector<std::string_view> split(std::string_view line) {
  std::vector<std::string_view> fields;
  std::size_t start = 0;
  for (;;) {
    std::size_t comma = line.find(',', start);
    if (comma == std::string_view::npos) {
      fields.push_back(line.substr(start));
      return fields;
    }
    fields.push_back(line.substr(start, comma - start));
    start = comma + 1;
  }
}

//! A relative path inside the recording: no absolute paths, no "..", no empty components.
bool safe_relative(std::string_view p) {
  if (p.empty() || p.front() == '/') return false;
  std::size_t start = 0;
  while (start <= p.size()) {
    std::size_t slash = p.find('/', start);
    std::string_view part =
        p.substr(start, slash == std::string_view::npos ? p.npos : slash - start);
    if (part.empty() || part == "." || part == "..") return false;
    if (slash == std::string_view::npos) break;
    start = slash + 1;
  }
  return p.find('\\') == std::string_view::npos;
}

}  // namespace

struct RecordingReader::Impl {
  std::filesystem::path folder;
  SessionMetadata session;
  std::vector<FrameRecord> records;
  std::vector<std::string> warnings;
};

RecordingReader::RecordingReader(const std::filesystem::path& folder)
    : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.folder = folder;
  m.session = read_session(folder);
  const std::filesystem::path csv = folder / kFramesFileName;
  const std::string csv_name = csv.string();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(csv, ec)) {
    if (m.session.finalized)
      throw InputError(csv_name, "", "missing (session.json says the recording is finalized)");
    m.warnings.push_back(csv_name +
                         ": missing; the writer stopped before its first frame (0 frames)");
    return;
  }
  const std::vector<unsigned char> bytes = detail::read_file_bytes(csv, kMaxCsvBytes);
  std::string_view text(reinterpret_cast<const char*>(bytes.data()), bytes.size());

  std::size_t pos = 0;
  std::size_t line_no = 0;
  bool header_seen = false;
  while (pos < text.size()) {
    ++line_no;
    std::size_t nl = text.find('\n', pos);
    const bool complete = nl != std::string_view::npos;
    std::string_view line = text.substr(pos, complete ? nl - pos : text.npos);
    pos = complete ? nl + 1 : text.size();
    if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
    if (!complete) {
      // A writer killed in the middle of appending a line leaves it without its newline.
      if (m.session.finalized)
        throw InputError(csv_name, line_place(line_no),
                         "last line is incomplete (no newline) in a finalized recording");
      m.warnings.push_back(csv_name + ": " + line_place(line_no) +
                           ": ignored an incomplete last line (the writer was interrupted)");
      break;
    }
    if (!header_seen) {
      if (line != kFramesCsvHeader)
        throw InputError(csv_name, line_place(line_no),
                         "expected the header \"" + std::string(kFramesCsvHeader) + "\", got \"" +
                             std::string(line.substr(0, 120)) + "\"");
      header_seen = true;
      continue;
    }
    if (line.empty()) {
      throw InputError(csv_name, line_place(line_no),
                       "empty line (expected 7 comma-separated fields)");
    }
    const auto f = split(line);
    if (f.size() != 7)
      throw InputError(csv_name, line_place(line_no),
                       "expected 7 comma-separated fields (" + std::string(kFramesCsvHeader) +
                           "), got " + std::to_string(f.size()));
    FrameRecord r;
    r.line = line_no;
    auto bad = [&](const char* field, std::string_view value, const char* expected) {
      throw InputError(csv_name, line_place(line_no),
                       std::string("field ") + field + ": expected " + expected + ", got \"" +
                           std::string(value.substr(0, 60)) + "\"");
    };
    if (!parse_int(f[0], r.index)) bad("index", f[0], "a non-negative integer");
    if (!parse_int(f[1], r.device_ts_us)) bad("device_ts_us", f[1], "an integer (microseconds)");
    if (!parse_int(f[2], r.host_ts_ns)) bad("host_ts_ns", f[2], "an integer (nanoseconds)");
    if (!safe_relative(f[3])) bad("depth", f[3], "a relative path inside the recording");
    if (!f[4].empty() && !safe_relative(f[4]))
      bad("color", f[4], "empty or a relative path inside the recording");
    if (!f[5].empty() && !safe_relative(f[5]))
      bad("confidence", f[5], "empty or a relative path inside the recording");
    if (!parse_int(f[6], r.flags)) bad("flags", f[6], "a non-negative integer");
    r.depth = std::string(f[3]);
    r.color = std::string(f[4]);
    r.confidence = std::string(f[5]);
    if (!m.records.empty() && r.index <= m.records.back().index)
      throw InputError(csv_name, line_place(line_no),
                       "field index: expected a value greater than the previous row's " +
                           std::to_string(m.records.back().index) + ", got " +
                           std::to_string(r.index));
    m.records.push_back(std::move(r));
  }
  if (!header_seen && m.session.finalized)
    throw InputError(csv_name, line_place(1), "missing header line in a finalized recording");

  // Every referenced file must exist. In a non-finalized recording the last row may reference
  // files whose rename did not reach the disk before a power loss: drop that row with a warning.
  for (std::size_t i = 0; i < m.records.size(); ++i) {
    const FrameRecord& r = m.records[i];
    for (const std::string* rel : {&r.depth, &r.color, &r.confidence}) {
      if (rel->empty()) continue;
      if (std::filesystem::is_regular_file(folder / *rel, ec)) continue;
      if (!m.session.finalized && i + 1 == m.records.size()) {
        m.warnings.push_back(csv_name + ": " + line_place(r.line) + ": ignored the last frame: " +
                             (folder / *rel).string() + " is missing (interrupted writer)");
        m.records.pop_back();
        break;
      }
      throw InputError((folder / *rel).string(), "",
                       "missing (referenced by " + csv_name + " " + line_place(r.line) + ")");
    }
  }
  if (m.session.finalized && m.session.frame_count && *m.session.frame_count != m.records.size())
    throw InputError(csv_name, "",
                     "has " + std::to_string(m.records.size()) +
                         " frame rows, session.json (finalized) says frame_count " +
                         std::to_string(*m.session.frame_count));
}

RecordingReader::~RecordingReader() = default;
RecordingReader::RecordingReader(RecordingReader&&) noexcept = default;
RecordingReader& RecordingReader::operator=(RecordingReader&&) noexcept = default;

const SessionMetadata& RecordingReader::session() const {
  return impl_->session;
}
std::size_t RecordingReader::frame_count() const {
  return impl_->records.size();
}
const std::vector<std::string>& RecordingReader::warnings() const {
  return impl_->warnings;
}
const std::filesystem::path& RecordingReader::folder() const {
  return impl_->folder;
}

const FrameRecord& RecordingReader::record(std::size_t i) const {
  if (i >= impl_->records.size())
    throw std::out_of_range("RecordingReader: frame " + std::to_string(i) + " of " +
                            std::to_string(impl_->records.size()));
  return impl_->records[i];
}

std::filesystem::path RecordingReader::color_file(std::size_t i) const {
  const FrameRecord& r = record(i);
  return r.color.empty() ? std::filesystem::path() : impl_->folder / r.color;
}

RgbImage RecordingReader::read_color(std::size_t i) const {
  const FrameRecord& r = record(i);
  if (r.color.empty())
    throw InputError((impl_->folder / kFramesFileName).string(), line_place(r.line),
                     "frame " + std::to_string(i) + " has no colour image");
  try {
    return detail::read_rgb_image(impl_->folder / r.color);
  } catch (const InputError& e) {
    throw InputError(e.what() + std::string(" (") + kFramesFileName + " " + line_place(r.line) +
                     ")");
  }
}

RangeFrame RecordingReader::read_frame(std::size_t i) const {
  const FrameRecord& r = record(i);
  const SessionMetadata& s = impl_->session;
  const std::string row = " (" + std::string(kFramesFileName) + " " + line_place(r.line) + ")";
  RangeFrame frame;
  frame.index = r.index;
  frame.device_ts_us = r.device_ts_us;
  frame.host_ts_ns = r.host_ts_ns;
  frame.depth_unit_m = s.unit_m;
  frame.K = s.K;
  frame.K.width = s.width;
  frame.K.height = s.height;
  try {
    frame.depth = detail::read_png16(impl_->folder / r.depth, s.width, s.height, "depth");
    if (!r.confidence.empty()) {
      Image<std::uint16_t> q =
          detail::read_png16(impl_->folder / r.confidence, s.width, s.height, "confidence");
      Image<float> c(q.width, q.height);
      for (std::size_t k = 0; k < q.data.size(); ++k)
        c.data[k] = static_cast<float>(q.data[k] / 65535.0);
      frame.confidence = std::move(c);
    }
    // Colour only where it is registered to the depth (pixel for pixel, the same size).
    if (!r.color.empty() && s.registration == "depth_to_color") {
      RgbImage rgb = detail::read_rgb_image(impl_->folder / r.color);
      if (rgb.width == s.width && rgb.height == s.height) frame.color = std::move(rgb);
    }
  } catch (const InputError& e) {
    throw InputError(e.what() + row);
  }
  return frame;
}

}  // namespace scanclean
