#include "scanclean/replay/recording_writer.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <system_error>

#include "png16.h"
#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"

namespace scanclean {

namespace {

std::string frame_file(const char* subfolder, std::size_t ordinal) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%06zu.png", ordinal);
  return std::string(subfolder) + "/" + buf;
}

// Makes the renames into `dir` durable. A failed fsync is an IoError (the frame would not
// survive a power loss); file systems that cannot sync a folder (EINVAL) are accepted.
void sync_directory(const std::filesystem::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY);
  if (fd < 0)
    throw IoError(dir.string() + ": cannot open the folder to sync it: " + std::strerror(errno));
  const int rc = ::fsync(fd);
  const int err = errno;
  ::close(fd);
  if (rc != 0 && err != EINVAL && err != EROFS)
    throw IoError(dir.string() + ": fsync of the folder failed: " + std::strerror(err));
}

}  // namespace

struct RecordingWriter::Impl {
  std::filesystem::path folder;
  SessionMetadata session;
  RecordingWriterOptions options;
  int csv_fd = -1;
  std::size_t written = 0;
  std::optional<std::uint64_t> last_index;
  bool has_confidence_dir = false;
  bool has_color_dir = false;

  void write(const RangeFrame& frame, const RgbImage* color);

  void ensure_dir(const char* name, bool& done) {
    if (done) return;
    std::error_code ec;
    std::filesystem::create_directories(folder / name, ec);
    if (ec) throw IoError((folder / name).string() + ": cannot create: " + ec.message());
    done = true;
  }

  ~Impl() {
    if (csv_fd >= 0) ::close(csv_fd);
  }

  std::string csv_path() const { return (folder / kFramesFileName).string(); }

  void append_line(const std::string& line) {
    // One write(2) per line: a kill leaves at most one partial trailing line.
    std::size_t done = 0;
    while (done < line.size()) {
      ssize_t n = ::write(csv_fd, line.data() + done, line.size() - done);
      if (n < 0) {
        if (errno == EINTR) continue;
        throw IoError(csv_path() + ": cannot append frame line: " + std::strerror(errno));
      }
      done += static_cast<std::size_t>(n);
    }
    if (options.sync_index && ::fsync(csv_fd) != 0)
      throw IoError(csv_path() + ": fsync failed: " + std::strerror(errno));
  }
};

RecordingWriter::RecordingWriter(const std::filesystem::path& folder,
                                 const SessionMetadata& session,
                                 const RecordingWriterOptions& options)
    : impl_(std::make_unique<Impl>()) {
  if (session.width <= 0 || session.height <= 0)
    throw OptionError("RecordingWriter: session depth size must be positive, got " +
                      std::to_string(session.width) + "x" + std::to_string(session.height));
  if (!(session.unit_m > 0))
    throw OptionError("RecordingWriter: session unit_m must be positive, got " +
                      std::to_string(session.unit_m));
  impl_->folder = folder;
  impl_->options = options;
  impl_->session = session;
  impl_->session.format = kRecordingFormat;
  impl_->session.finalized = false;
  impl_->session.frame_count.reset();
  impl_->session.K.width = session.width;
  impl_->session.K.height = session.height;
  if (impl_->session.created.empty()) impl_->session.created = utc_now_iso8601();

  std::error_code ec;
  std::filesystem::create_directories(folder / "depth", ec);
  if (ec) throw IoError(folder.string() + ": cannot create the recording folder: " + ec.message());
  if (std::filesystem::exists(folder / kSessionFileName, ec) ||
      std::filesystem::exists(folder / kFramesFileName, ec))
    throw IoError(folder.string() +
                  ": already holds a recording (session.json or frames.csv); refusing to "
                  "overwrite it, choose a new folder");
  // Order matters for crash safety: session.json, then the index with its header.
  write_session(folder, impl_->session);
  write_file_atomically(
      folder / kFramesFileName, [](std::ostream& out) { out << kFramesCsvHeader << '\n'; }, true);
  sync_directory(folder);
  impl_->csv_fd = ::open((folder / kFramesFileName).c_str(), O_WRONLY | O_APPEND | O_CLOEXEC);
  if (impl_->csv_fd < 0)
    throw IoError(impl_->csv_path() + ": cannot open for appending: " + std::strerror(errno));
}

RecordingWriter::~RecordingWriter() = default;
RecordingWriter::RecordingWriter(RecordingWriter&&) noexcept = default;
RecordingWriter& RecordingWriter::operator=(RecordingWriter&&) noexcept = default;

void RecordingWriter::write(const RangeFrame& frame) {
  impl_->write(frame, nullptr);
}

void RecordingWriter::write(const RangeFrame& frame, const RgbImage& color) {
  impl_->write(frame, &color);
}

void RecordingWriter::Impl::write(const RangeFrame& frame, const RgbImage* color) {
  Impl& m = *this;
  const std::string where = m.csv_path();
  const std::string place =
      "frame " + std::to_string(m.written) + " (index " + std::to_string(frame.index) + ")";
  if (frame.depth.empty())
    throw InputError(where, place,
                     "frame has no depth image (format v1 stores depth; points-only frames "
                     "cannot be recorded)");
  if (frame.depth.width != m.session.width || frame.depth.height != m.session.height ||
      frame.depth.data.size() != static_cast<std::size_t>(frame.depth.width) * frame.depth.height)
    throw InputError(where, place,
                     "depth image is " + std::to_string(frame.depth.width) + "x" +
                         std::to_string(frame.depth.height) + ", the session is " +
                         std::to_string(m.session.width) + "x" + std::to_string(m.session.height));
  if (std::abs(frame.depth_unit_m - m.session.unit_m) > 1e-12 * m.session.unit_m)
    throw InputError(where, place,
                     "depth unit " + std::to_string(frame.depth_unit_m) +
                         " m differs from the session's " + std::to_string(m.session.unit_m) +
                         " m");
  if (m.last_index && frame.index <= *m.last_index)
    throw InputError(where, place,
                     "frame index " + std::to_string(frame.index) +
                         " is not greater than the previous " + std::to_string(*m.last_index));
  if (frame.confidence &&
      (frame.confidence->width != m.session.width || frame.confidence->height != m.session.height))
    throw InputError(where, place, "confidence image size differs from the depth image size");
  if (color &&
      (color->empty() || color->data.size() != static_cast<std::size_t>(color->width) *
                                                   static_cast<std::size_t>(color->height)))
    throw InputError(where, place, "colour image is empty or inconsistent");

  if (m.session.finalized) {  // writing after finish(): the recording is open again
    m.session.finalized = false;
    m.session.frame_count.reset();
    write_session(m.folder, m.session);
  }

  const std::string depth_rel = frame_file("depth", m.written);
  detail::write_png16_atomically(m.folder / depth_rel, frame.depth);
  std::string conf_rel;
  if (frame.confidence) {
    m.ensure_dir("confidence", m.has_confidence_dir);
    Image<std::uint16_t> q(frame.confidence->width, frame.confidence->height);
    std::transform(frame.confidence->data.begin(), frame.confidence->data.end(), q.data.begin(),
                   [](float c) {
                     if (!(c > 0.0f)) return std::uint16_t{0};  // also NaN -> 0
                     if (c >= 1.0f) return std::uint16_t{65535};
                     return static_cast<std::uint16_t>(std::lround(c * 65535.0));
                   });
    conf_rel = frame_file("confidence", m.written);
    detail::write_png16_atomically(m.folder / conf_rel, q);
  }
  std::string color_rel;
  if (color) {
    m.ensure_dir("color", m.has_color_dir);
    color_rel = frame_file("color", m.written);
    detail::write_rgb_png_atomically(m.folder / color_rel, *color);
  }
  // The frame's files are durable (fsynced, renamed); make the renames durable, then index.
  if (m.options.sync_index) {
    sync_directory(m.folder / "depth");
    if (frame.confidence) sync_directory(m.folder / "confidence");
    if (color) sync_directory(m.folder / "color");
  }
  std::string line = std::to_string(frame.index) + "," + std::to_string(frame.device_ts_us) + "," +
                     std::to_string(frame.host_ts_ns) + "," + depth_rel + "," + color_rel + "," +
                     conf_rel + ",0\n";
  m.append_line(line);
  m.last_index = frame.index;
  ++m.written;
}

void RecordingWriter::finish() {
  Impl& m = *impl_;
  if (m.session.finalized) return;
  m.session.finalized = true;
  m.session.frame_count = m.written;
  write_session(m.folder, m.session);
  sync_directory(m.folder);
}

std::size_t RecordingWriter::frames_written() const {
  return impl_->written;
}
const std::filesystem::path& RecordingWriter::folder() const {
  return impl_->folder;
}
const SessionMetadata& RecordingWriter::session() const {
  return impl_->session;
}

}  // namespace scanclean
