#include "scanclean/drivers/sl_calibration.h"

#include <Eigen/Dense>
#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <opencv2/core.hpp>
#include <optional>
#include <sstream>
#include <string_view>
#include <vector>

#include "scanclean/core/atomic_file.h"
#include "scanclean/core/errors.h"
#include "sl_opencv.h"

namespace scanclean {
namespace {

constexpr std::size_t kMaxCalibrationBytes = 1 << 20;
constexpr int kMaxMatrixSide = 16;

// One top-level value of a calibration file: numbers (a matrix with rows x cols, or a plain
// sequence / scalar with rows = 1) or a string.
struct Value {
  bool is_string = false;
  std::string text;
  std::vector<double> numbers;
  int rows = 0, cols = 0;
  int line = 0;  // where the key is
};
using Fields = std::map<std::string, Value>;

// A strict reader of the subset of OpenCV FileStorage text (YAML and XML) that calibration files
// use. OpenCV's own parser is not trusted with arbitrary bytes (it crashes, loops or allocates
// without bound on small malformed files); this one checks every byte it consumes and bounds
// every size.
class Parser {
 public:
  Parser(std::string_view text, const std::string& name) : t_(text), name_(name) {}

  Fields parse() {
    if (t_.size() > kMaxCalibrationBytes)
      fail(0, "larger than " + std::to_string(kMaxCalibrationBytes) + " bytes");
    for (std::size_t i = 0; i < t_.size(); ++i) {
      const unsigned char ch = static_cast<unsigned char>(t_[i]);
      if (ch == '\n') newlines_.push_back(i);
      if (ch == 0 || (ch < 32 && ch != '\n' && ch != '\r' && ch != '\t') || ch >= 127)
        fail(line_at(i), "byte " + std::to_string(ch) + " at offset " + std::to_string(i) +
                             ": expected printable ASCII text (a YAML or XML calibration)");
    }
    std::size_t i = 0;
    skip_space(i);
    if (t_.substr(i, 5) == "<?xml" || t_.substr(i, 1) == "<") return parse_xml();
    return parse_yaml();
  }

 private:
  [[noreturn]] void fail(int line, const std::string& what) const {
    throw InputError(name_, line > 0 ? "line " + std::to_string(line) : std::string(), what);
  }
  // 1-based line of a byte offset (binary search in the newline offsets, O(log n)).
  int line_at(std::size_t pos) const {
    return 1 + static_cast<int>(std::lower_bound(newlines_.begin(), newlines_.end(), pos) -
                                newlines_.begin());
  }
  void skip_space(std::size_t& i) const {
    while (i < t_.size() && std::isspace(static_cast<unsigned char>(t_[i]))) ++i;
  }
  static bool is_key_char(char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-';
  }

  // Numbers separated by spaces / commas (and newlines), every token checked.
  std::vector<double> numbers(std::string_view s, int line, const std::string& key) const {
    std::vector<double> out;
    std::size_t i = 0;
    while (i < s.size()) {
      while (i < s.size() && (std::isspace(static_cast<unsigned char>(s[i])) || s[i] == ',')) ++i;
      if (i >= s.size()) break;
      std::size_t j = i;
      while (j < s.size() && !std::isspace(static_cast<unsigned char>(s[j])) && s[j] != ',') ++j;
      const std::string tok(s.substr(i, j - i));
      if (tok.size() > 40) fail(line, "field '" + key + "': number token too long");
      char* end = nullptr;
      const double v = std::strtod(tok.c_str(), &end);
      if (end != tok.c_str() + tok.size() || tok.find_first_of("xXpP") != std::string::npos)
        fail(line, "field '" + key + "': expected a number, got '" + tok + "'");
      if (!std::isfinite(v)) fail(line, "field '" + key + "': contains a non-finite value");
      out.push_back(v);
      if (out.size() > kMaxMatrixSide * kMaxMatrixSide)
        fail(line, "field '" + key + "': more than " +
                       std::to_string(kMaxMatrixSide * kMaxMatrixSide) + " values");
      i = j;
    }
    return out;
  }

  int side(std::string_view s, int line, const std::string& key, const char* what) const {
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
    bool digits = !s.empty() && s.size() <= 2;
    for (char c : s) digits = digits && std::isdigit(static_cast<unsigned char>(c));
    const int v = digits ? std::stoi(std::string(s)) : 0;
    if (v < 1 || v > kMaxMatrixSide)
      fail(line, "field '" + key + "': " + what + " must be an integer 1.." +
                     std::to_string(kMaxMatrixSide) + ", got '" + std::string(s.substr(0, 20)) +
                     "'");
    return v;
  }

  void check_dt(std::string_view dt, int line, const std::string& key) const {
    if (dt != "d" && dt != "f" && dt != "i" && dt != "u" && dt != "s" && dt != "w" && dt != "c")
      fail(line, "field '" + key + "': dt '" + std::string(dt) + "' is not a single-channel type");
  }

  void add(Fields& f, const std::string& key, Value v) const {
    if (key.empty() || key.size() > 64) fail(v.line, "expected a field name of 1..64 characters");
    if (f.count(key)) fail(v.line, "field '" + key + "' appears twice");
    if (f.size() >= 64) fail(v.line, "more than 64 fields");
    f.emplace(key, std::move(v));
  }

  Value matrix(int rows, int cols, std::vector<double> data, int line,
               const std::string& key) const {
    if (data.size() != static_cast<std::size_t>(rows) * static_cast<std::size_t>(cols))
      fail(line, "field '" + key + "': rows x cols = " + std::to_string(rows) + "x" +
                     std::to_string(cols) + " but " + std::to_string(data.size()) + " values");
    Value v;
    v.rows = rows;
    v.cols = cols;
    v.numbers = std::move(data);
    v.line = line;
    return v;
  }

  // A scalar or inline sequence text: numbers (rows 1) or a string.
  Value scalar(std::string_view s, int line, const std::string& key) const {
    Value v;
    v.line = line;
    if (s.size() >= 2 && s.front() == '"' && s.back() == '"') {
      v.is_string = true;
      v.text = std::string(s.substr(1, s.size() - 2));
      return v;
    }
    const char c0 = s.empty() ? ' ' : s.front();
    if (std::isdigit(static_cast<unsigned char>(c0)) || c0 == '-' || c0 == '+' || c0 == '.') {
      v.numbers = numbers(s, line, key);
      v.rows = 1;
      v.cols = static_cast<int>(v.numbers.size());
      if (v.numbers.empty()) fail(line, "field '" + key + "': empty");
      return v;
    }
    for (char c : s)
      if (!is_key_char(c) && c != '.' && c != ' ')
        fail(line, "field '" + key + "': unexpected character '" + std::string(1, c) + "'");
    v.is_string = true;
    v.text = std::string(s);
    return v;
  }

  // ---- YAML (what cv::FileStorage writes) ----
  Fields parse_yaml() {
    Fields f;
    std::vector<std::pair<int, std::string_view>> lines;
    {
      std::size_t b = 0;
      int n = 1;
      while (b <= t_.size()) {
        std::size_t e = t_.find('\n', b);
        if (e == std::string_view::npos) e = t_.size();
        std::string_view l = t_.substr(b, e - b);
        if (!l.empty() && l.back() == '\r') l.remove_suffix(1);
        lines.emplace_back(n++, l);
        b = e + 1;
      }
    }
    auto trim = [](std::string_view s) {
      while (!s.empty() && std::isspace(static_cast<unsigned char>(s.front()))) s.remove_prefix(1);
      while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.remove_suffix(1);
      return s;
    };
    auto strip_comment = [](std::string_view s) {
      const auto h = s.find('#');
      return h == std::string_view::npos ? s : s.substr(0, h);
    };
    std::size_t k = 0;
    bool header = false;
    // The bracketed text starting at `first` (after '['), spanning lines up to ']'.
    auto bracket = [&](std::string_view first, std::size_t& idx, int line, const std::string& key) {
      std::string acc;
      std::string_view cur = first;
      for (;;) {
        const auto close = cur.find(']');
        if (close != std::string_view::npos) {
          if (!trim(cur.substr(close + 1)).empty())
            fail(lines[idx].first, "field '" + key + "': text after ']'");
          acc.append(cur.substr(0, close));
          return acc;
        }
        acc.append(cur);
        acc.push_back(' ');
        if (++idx >= lines.size()) fail(line, "field '" + key + "': '[' without ']'");
        cur = strip_comment(lines[idx].second);
        if (acc.size() > 16384) fail(line, "field '" + key + "': sequence too long");
      }
    };
    for (; k < lines.size(); ++k) {
      const int ln = lines[k].first;
      std::string_view l = strip_comment(lines[k].second);
      if (trim(l).empty()) continue;
      if (!header && (l.substr(0, 5) == "%YAML")) {
        header = true;
        continue;
      }
      if (trim(l) == "---") continue;
      if (std::isspace(static_cast<unsigned char>(l.front())))
        fail(ln, "unexpected indentation (expected 'name: value')");
      const auto colon = l.find(':');
      if (colon == std::string_view::npos) fail(ln, "expected 'name: value'");
      const std::string key(l.substr(0, colon));
      for (char c : key)
        if (!is_key_char(c)) fail(ln, "field name '" + key + "': unexpected character");
      std::string_view rest = trim(l.substr(colon + 1));
      if (rest.substr(0, 2) == "!!") {
        if (rest != "!!opencv-matrix")
          fail(ln,
               "field '" + key + "': expected !!opencv-matrix, got '" + std::string(rest) + "'");
        int rows = 0, cols = 0;
        bool dt = false;
        std::optional<std::vector<double>> data;
        while (k + 1 < lines.size()) {
          std::string_view m = strip_comment(lines[k + 1].second);
          if (trim(m).empty()) {
            ++k;
            continue;
          }
          if (!std::isspace(static_cast<unsigned char>(m.front()))) break;
          ++k;
          const int mln = lines[k].first;
          m = trim(m);
          const auto c2 = m.find(':');
          if (c2 == std::string_view::npos)
            fail(mln, "field '" + key + "': expected 'name: value'");
          const std::string_view sub = m.substr(0, c2), val = trim(m.substr(c2 + 1));
          if (sub == "rows") {
            rows = side(val, mln, key, "rows");
          } else if (sub == "cols") {
            cols = side(val, mln, key, "cols");
          } else if (sub == "dt") {
            check_dt(val, mln, key);
            dt = true;
          } else if (sub == "data") {
            if (val.empty() || val.front() != '[')
              fail(mln, "field '" + key + "': expected data: [ ... ]");
            data = numbers(bracket(val.substr(1), k, mln, key), mln, key);
          } else {
            fail(mln, "field '" + key + "': unexpected '" + std::string(sub) + "'");
          }
        }
        if (!rows || !cols || !dt || !data)
          fail(ln, "field '" + key + "': expected rows, cols, dt and data");
        add(f, key, matrix(rows, cols, std::move(*data), ln, key));
      } else if (!rest.empty() && rest.front() == '[') {
        Value v;
        v.line = ln;
        v.numbers = numbers(bracket(rest.substr(1), k, ln, key), ln, key);
        v.rows = 1;
        v.cols = static_cast<int>(v.numbers.size());
        if (v.numbers.empty()) fail(ln, "field '" + key + "': empty sequence");
        add(f, key, std::move(v));
      } else {
        if (rest.empty()) fail(ln, "field '" + key + "': no value");
        add(f, key, scalar(rest, ln, key));
      }
    }
    return f;
  }

  // ---- XML (what cv::FileStorage writes) ----
  struct Tag {
    std::string name;
    bool closing = false;
    bool self_closing = false;
    std::size_t end = 0;  // one past '>'
  };

  Tag tag(std::size_t i) const {
    // t_[i] == '<'
    const int ln = line_at(i);
    Tag tg;
    std::size_t j = i + 1;
    if (j < t_.size() && t_[j] == '/') {
      tg.closing = true;
      ++j;
    }
    const std::size_t n0 = j;
    while (j < t_.size() && is_key_char(t_[j])) ++j;
    tg.name = std::string(t_.substr(n0, j - n0));
    if (tg.name.empty() || tg.name.size() > 64) fail(ln, "expected an XML element name");
    // Attributes: name="value" pairs only.
    for (;;) {
      while (j < t_.size() && std::isspace(static_cast<unsigned char>(t_[j]))) ++j;
      if (j >= t_.size()) fail(ln, "element <" + tg.name + "> not closed with '>'");
      if (t_[j] == '>') break;
      if (t_[j] == '/' && j + 1 < t_.size() && t_[j + 1] == '>' && !tg.closing) {
        tg.self_closing = true;
        ++j;
        break;
      }
      if (tg.closing) fail(ln, "closing element </" + tg.name + "> with attributes");
      const std::size_t a0 = j;
      while (j < t_.size() && is_key_char(t_[j])) ++j;
      if (j == a0 || j + 1 >= t_.size() || t_[j] != '=' || t_[j + 1] != '"')
        fail(ln, "element <" + tg.name + ">: expected name=\"value\" attributes");
      const auto q = t_.find('"', j + 2);
      if (q == std::string_view::npos) fail(ln, "element <" + tg.name + ">: unterminated '\"'");
      if (t_.substr(j + 2, q - j - 2).find_first_of("<>") != std::string_view::npos)
        fail(ln, "element <" + tg.name + ">: '<' or '>' in an attribute");
      j = q + 1;
    }
    tg.end = j + 1;
    return tg;
  }

  void skip_misc(std::size_t& i) const {
    for (;;) {
      skip_space(i);
      if (t_.substr(i, 2) == "<?") {
        const auto e = t_.find("?>", i);
        if (e == std::string_view::npos) fail(line_at(i), "unterminated '<?'");
        i = e + 2;
      } else if (t_.substr(i, 4) == "<!--") {
        const auto e = t_.find("-->", i);
        if (e == std::string_view::npos) fail(line_at(i), "unterminated comment");
        i = e + 3;
      } else {
        return;
      }
    }
  }

  // Text up to the next '<' (which must open the closing tag of `name` or a child).
  std::string_view text_until_tag(std::size_t& i) const {
    const auto e = t_.find('<', i);
    if (e == std::string_view::npos) fail(line_at(i), "unexpected end of file");
    std::string_view s = t_.substr(i, e - i);
    if (s.find('>') != std::string_view::npos) fail(line_at(i), "stray '>'");
    i = e;
    return s;
  }

  void expect_close(std::size_t& i, const std::string& name) const {
    skip_misc(i);
    if (i >= t_.size() || t_[i] != '<') fail(line_at(i), "expected </" + name + ">");
    const Tag c = tag(i);
    if (!c.closing || c.name != name)
      fail(line_at(i), "expected </" + name + ">, got <" + (c.closing ? "/" : "") + c.name + ">");
    i = c.end;
  }

  Fields parse_xml() {
    Fields f;
    std::size_t i = 0;
    skip_misc(i);
    if (i >= t_.size() || t_[i] != '<') fail(line_at(i), "expected <opencv_storage>");
    const Tag root = tag(i);
    if (root.closing || root.self_closing || root.name != "opencv_storage")
      fail(line_at(i), "expected <opencv_storage>, got <" + root.name + ">");
    i = root.end;
    for (;;) {
      skip_misc(i);
      if (i >= t_.size()) fail(line_at(i), "missing </opencv_storage>");
      if (t_[i] != '<') fail(line_at(i), "expected an element, got text");
      const int ln = line_at(i);
      const Tag el = tag(i);
      if (el.closing) {
        if (el.name != "opencv_storage") fail(ln, "unexpected </" + el.name + ">");
        i = el.end;
        skip_misc(i);
        if (i != t_.size()) fail(line_at(i), "text after </opencv_storage>");
        return f;
      }
      if (el.self_closing) fail(ln, "field '" + el.name + "': empty element");
      i = el.end;
      const std::size_t save = i;
      skip_space(i);
      if (t_.substr(i, 1) == "<" && t_.substr(i, 2) != "</") {
        // opencv-matrix: <rows> <cols> <dt> <data> children.
        int rows = 0, cols = 0;
        bool dt = false;
        std::optional<std::vector<double>> data;
        for (;;) {
          skip_misc(i);
          if (i >= t_.size()) fail(ln, "field '" + el.name + "': unexpected end of file");
          const int cl = line_at(i);
          const Tag ch = tag(i);
          if (ch.closing) {
            if (ch.name != el.name) fail(cl, "expected </" + el.name + ">, got </" + ch.name + ">");
            i = ch.end;
            break;
          }
          if (ch.self_closing) fail(cl, "field '" + el.name + "': empty <" + ch.name + ">");
          i = ch.end;
          const std::string_view body = text_until_tag(i);
          if (ch.name == "rows")
            rows = side(body, cl, el.name, "rows");
          else if (ch.name == "cols")
            cols = side(body, cl, el.name, "cols");
          else if (ch.name == "dt") {
            std::string_view d = body;
            while (!d.empty() && std::isspace(static_cast<unsigned char>(d.front())))
              d.remove_prefix(1);
            while (!d.empty() && std::isspace(static_cast<unsigned char>(d.back())))
              d.remove_suffix(1);
            check_dt(d, cl, el.name);
            dt = true;
          } else if (ch.name == "data")
            data = numbers(body, cl, el.name);
          else
            fail(cl, "field '" + el.name + "': unexpected <" + ch.name + ">");
          expect_close(i, ch.name);
        }
        if (!rows || !cols || !dt || !data)
          fail(ln, "field '" + el.name + "': expected <rows>, <cols>, <dt> and <data>");
        add(f, el.name, matrix(rows, cols, std::move(*data), ln, el.name));
      } else {
        i = save;
        std::string_view body = text_until_tag(i);
        while (!body.empty() && std::isspace(static_cast<unsigned char>(body.front())))
          body.remove_prefix(1);
        while (!body.empty() && std::isspace(static_cast<unsigned char>(body.back())))
          body.remove_suffix(1);
        if (body.empty()) fail(ln, "field '" + el.name + "': empty");
        add(f, el.name, scalar(body, ln, el.name));
        expect_close(i, el.name);
      }
    }
  }

  std::string_view t_;
  const std::string& name_;
  std::vector<std::size_t> newlines_;  // offsets of '\n', filled by the byte check
};

std::string describe_shape(const Value& v) {
  return std::to_string(v.rows) + "x" + std::to_string(v.cols);
}

class CalibReader {
 public:
  CalibReader(const std::string& file, const Fields& f) : file_(file), f_(f) {}

  bool has(const char* name) const { return f_.count(name) != 0; }

  const Value& numeric(const char* name) const {
    const auto it = f_.find(name);
    if (it == f_.end()) throw InputError(file_, std::string("field '") + name + "'", "missing");
    if (it->second.is_string || it->second.numbers.empty())
      throw InputError(file_, where(it->second, name), "expected a numeric matrix");
    return it->second;
  }

  static std::string where(const Value& v, const char* name) {
    return "line " + std::to_string(v.line) + ": field '" + name + "'";
  }

  Eigen::Matrix3d mat3(const char* name) const {
    const Value& m = numeric(name);
    if (m.rows != 3 || m.cols != 3)
      throw InputError(file_, where(m, name), "expected a 3x3 matrix, got " + describe_shape(m));
    Eigen::Matrix3d e;
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) e(r, c) = m.numbers[static_cast<std::size_t>(r * 3 + c)];
    return e;
  }

  Eigen::Vector3d vec3(const char* name) const {
    const Value& m = numeric(name);
    if (m.numbers.size() != 3)
      throw InputError(file_, where(m, name), "expected 3 values, got " + describe_shape(m));
    return {m.numbers[0], m.numbers[1], m.numbers[2]};
  }

  std::array<double, 5> distortion(const char* name) const {
    const Value& m = numeric(name);
    const std::size_t n = m.numbers.size();
    if (n != 4 && n != 5 && n != 8 && n != 12 && n != 14)
      throw InputError(
          file_, where(m, name),
          "expected 4, 5, 8, 12 or 14 distortion coefficients, got " + describe_shape(m));
    std::array<double, 5> d{};
    for (std::size_t i = 0; i < std::min<std::size_t>(n, 5); ++i) d[i] = m.numbers[i];
    for (std::size_t i = 5; i < n; ++i)
      if (m.numbers[i] != 0.0)
        throw InputError(file_, where(m, name),
                         "only the 5-coefficient model (k1 k2 p1 p2 k3) is supported; "
                         "coefficient " +
                             std::to_string(i) + " is not zero");
    return d;
  }

  //! Two positive integers, in the file's order.
  std::array<int, 2> size2(const char* name) const {
    const Value& m = numeric(name);
    if (m.numbers.size() != 2)
      throw InputError(file_, where(m, name), "expected 2 values, got " + describe_shape(m));
    std::array<int, 2> out{};
    for (std::size_t i = 0; i < 2; ++i) {
      const double v = m.numbers[i];
      if (v < 1 || v > 65535 || v != std::floor(v))
        throw InputError(file_, where(m, name), "expected positive integer sizes");
      out[i] = static_cast<int>(v);
    }
    return out;
  }

  double scalar(const char* name, double fallback) const {
    const auto it = f_.find(name);
    if (it == f_.end()) return fallback;
    if (it->second.is_string || it->second.numbers.size() != 1)
      throw InputError(file_, where(it->second, name), "expected a number");
    return it->second.numbers[0];
  }

  std::string string(const char* name) const {
    const auto it = f_.find(name);
    if (it == f_.end()) return {};
    if (!it->second.is_string)
      throw InputError(file_, where(it->second, name), "expected a string");
    return it->second.text;
  }

  void intrinsics(const char* name, Intrinsics& K) const {
    const Eigen::Matrix3d m = mat3(name);
    const std::string at = where(f_.at(name), name);
    K.fx = m(0, 0);
    K.fy = m(1, 1);
    K.cx = m(0, 2);
    K.cy = m(1, 2);
    K.source = "calibration";
    if (!(K.fx > 0) || !(K.fy > 0) || m(1, 0) != 0 || m(2, 0) != 0 || m(2, 1) != 0 ||
        std::abs(m(2, 2) - 1) > 1e-9)
      throw InputError(file_, at,
                       "expected a camera matrix [fx 0 cx; 0 fy cy; 0 0 1] with fx, fy > 0");
    if (std::abs(m(0, 1)) > 1e-9 * K.fx)
      throw InputError(file_, at, "a skewed camera matrix is not supported");
  }

 private:
  const std::string& file_;
  const Fields& f_;
};

double unit_to_metres(const std::string& file, const std::string& unit) {
  if (unit == "m") return 1.0;
  if (unit == "cm") return 0.01;
  if (unit == "mm") return 0.001;
  if (unit == "um") return 1e-6;
  throw InputError(file, "field 'units'",
                   "expected \"m\", \"cm\", \"mm\" or \"um\", got \"" + unit + "\"");
}

}  // namespace

SlCalibration parse_sl_calibration(std::string_view text, const std::string& name) {
  const Fields fields = Parser(text, name).parse();
  CalibReader r(name, fields);
  SlCalibration c;
  if (r.has("cam_K") || !r.has("cam_int")) {
    c.layout = "scanclean";
    r.intrinsics("cam_K", c.camera);
    c.camera.dist = r.distortion("cam_dist");
    r.intrinsics("proj_K", c.projector);
    c.projector.dist = r.distortion("proj_dist");
    c.R = r.mat3("R");
    c.T = r.vec3("T");
    const auto cs = r.size2("cam_size");
    c.camera.width = cs[0];
    c.camera.height = cs[1];
    const auto ps = r.size2("proj_size");
    c.projector.width = ps[0];
    c.projector.height = ps[1];
    const std::string units = r.string("units");
    if (units.empty()) throw InputError(name, "field 'units'", "missing");
    c.unit_m = unit_to_metres(name, units);
    c.rms = r.scalar("rms", 0.0);
    const double step = r.scalar("graycode_step", 1.0);
    if (step < 1 || step > 64 || step != std::floor(step))
      throw InputError(name, "field 'graycode_step'", "expected an integer 1..64");
    c.graycode_step = static_cast<int>(step);
  } else {
    c.layout = "kamino410";
    r.intrinsics("cam_int", c.camera);
    c.camera.dist = r.distortion("cam_dist");
    r.intrinsics("proj_int", c.projector);
    c.projector.dist = r.distortion("proj_dist");
    c.R = r.mat3("roration");  // sic, the field name in kamino410/procam-calibration
    c.T = r.vec3("translation");
    const auto shape = r.size2("img_shape");  // rows, cols
    c.camera.height = shape[0];
    c.camera.width = shape[1];
    c.unit_m = 0.001;  // chessboard square units, assumed millimetres (not stated)
    c.unit_assumed = true;
    c.rms = r.scalar("rms", 0.0);
  }
  const double orth = (c.R.transpose() * c.R - Eigen::Matrix3d::Identity()).norm();
  if (!(orth <= 1e-4) || c.R.determinant() < 0)
    throw InputError(name, c.layout == "kamino410" ? "field 'roration'" : "field 'R'",
                     "not a rotation matrix (|R^T R - I| = " + std::to_string(orth) + ")");
  return c;
}

SlCalibration read_sl_calibration(const std::filesystem::path& file) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(file, ec))
    throw InputError(file.string(), "", "calibration file not found");
  const auto size = std::filesystem::file_size(file, ec);
  if (ec) throw IoError(file.string() + ": cannot read the size: " + ec.message());
  if (size > kMaxCalibrationBytes)
    throw InputError(
        file.string(), "",
        "larger than " + std::to_string(kMaxCalibrationBytes) + " bytes: not a calibration file");
  std::ifstream in(file, std::ios::binary);
  if (!in) throw IoError(file.string() + ": cannot open");
  std::string text(static_cast<std::size_t>(size), '\0');
  in.read(text.data(), static_cast<std::streamsize>(size));
  if (static_cast<std::uintmax_t>(in.gcount()) != size)
    throw IoError(file.string() + ": read error");
  SlCalibration c = parse_sl_calibration(text, file.string());
  c.file = file;
  return c;
}

void write_sl_calibration(const std::filesystem::path& file, const SlCalibration& c) {
  const auto K = sl_detail::camera_matrix;
  const auto D = sl_detail::dist_coeffs;
  cv::Mat R(3, 3, CV_64F), T(3, 1, CV_64F);
  for (int i = 0; i < 3; ++i) {
    T.at<double>(i) = c.T(i);
    for (int j = 0; j < 3; ++j) R.at<double>(i, j) = c.R(i, j);
  }
  const char* unit = nullptr;
  for (const auto& [name, metres] :
       {std::pair{"m", 1.0}, {"cm", 0.01}, {"mm", 0.001}, {"um", 1e-6}})
    if (std::abs(c.unit_m - metres) <= 1e-9 * metres) unit = name;
  if (!unit)
    throw OptionError("write_sl_calibration: unit_m must be 1, 0.01, 0.001 or 1e-6, got " +
                      std::to_string(c.unit_m));
  cv::FileStorage fs(".yml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY);
  fs << "cam_K" << K(c.camera) << "cam_dist" << D(c.camera);
  fs << "proj_K" << K(c.projector) << "proj_dist" << D(c.projector);
  fs << "R" << R << "T" << T;
  fs << "cam_size" << std::vector<int>{c.camera.width, c.camera.height};
  fs << "proj_size" << std::vector<int>{c.projector.width, c.projector.height};
  fs << "units" << std::string(unit) << "rms" << c.rms << "graycode_step" << c.graycode_step;
  const std::string text = fs.releaseAndGetString();
  write_file_atomically(
      file, [&](std::ostream& out) { out << text; }, false);
}

}  // namespace scanclean

namespace scanclean {

void write_sl_calibration_kamino(const std::filesystem::path& file, const SlCalibration& c) {
  std::ostringstream o;
  o.precision(17);
  auto mat = [&](const char* name, int rows, int cols, const std::vector<double>& v) {
    o << "<" << name << " type_id=\"opencv-matrix\">\n  <rows>" << rows << "</rows>\n  <cols>"
      << cols << "</cols>\n  <dt>d</dt>\n  <data>\n   ";
    for (double x : v) o << " " << x;
    o << "</data></" << name << ">\n";
  };
  auto K = [](const Intrinsics& k) {
    return std::vector<double>{k.fx, 0, k.cx, 0, k.fy, k.cy, 0, 0, 1};
  };
  auto D = [](const Intrinsics& k) { return std::vector<double>(k.dist.begin(), k.dist.end()); };
  const double to_mm = c.unit_m / 0.001;
  o << "<?xml version=\"1.0\"?>\n<opencv_storage>\n";
  mat("img_shape", 2, 1, {double(c.camera.height), double(c.camera.width)});
  o << "<rms>" << c.rms << "</rms>\n";
  mat("cam_int", 3, 3, K(c.camera));
  mat("cam_dist", 1, 5, D(c.camera));
  mat("proj_int", 3, 3, K(c.projector));
  mat("proj_dist", 1, 5, D(c.projector));
  std::vector<double> R, T;
  for (int i = 0; i < 3; ++i) {
    T.push_back(c.T(i) * to_mm);
    for (int j = 0; j < 3; ++j) R.push_back(c.R(i, j));
  }
  mat("roration", 3, 3, R);  // sic, kamino410's field name
  mat("translation", 3, 1, T);
  o << "</opencv_storage>\n";
  const std::string text = o.str();
  write_file_atomically(
      file, [&](std::ostream& out) { out << text; }, false);
}

}  // namespace scanclean
