#include "tools/cli/map_picture.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numbers>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <tuple>
#include <unordered_map>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "tools/io/atomic_file.h"
#include "tools/io/csv.h"
#include "tools/io/number_text.h"

namespace fastslam::tools {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// What is read.

struct Point {
  double x = 0, y = 0;
};

// A path vertex; a new segment starts where a path read near the zoom window comes back into it.
struct Vertex {
  double x = 0, y = 0;
  std::uint64_t segment = 0;
};

struct Estimate {
  double id = 0, x = 0, y = 0, sxx = 0, sxy = 0, syy = 0;
};

// An axis-aligned box in metres, empty until a point is added.
struct Box {
  double x0 = kInf, x1 = -kInf, y0 = kInf, y1 = -kInf;

  bool empty() const { return x0 > x1; }
  void add(double x, double y) {
    x0 = std::min(x0, x);
    x1 = std::max(x1, x);
    y0 = std::min(y0, y);
    y1 = std::max(y1, y);
  }
  void add(const Box& b) {
    if (b.empty()) return;
    add(b.x0, b.y0);
    add(b.x1, b.y1);
  }
  bool contains(double x, double y) const { return x0 <= x && x <= x1 && y0 <= y && y <= y1; }
};

// The rows of a path inside `near`, at full resolution up to kMaxPathPoints, a new segment each
// time the path comes back (plot_run.py's read_near).
class NearPath {
 public:
  explicit NearPath(const Box& near) : near_(near) {}
  void offer(std::uint64_t row, double x, double y) {
    if (near_.contains(x, y)) {
      kept_.add(row, {x, y, segment_});
      inside_ = true;
    } else if (inside_) {
      ++segment_;
      inside_ = false;
    }
  }
  std::vector<Vertex> values() const { return kept_.values(); }

 private:
  Box near_;
  Thinned<Vertex> kept_{kMaxPathPoints};
  std::uint64_t segment_ = 0;
  bool inside_ = false;
};

const std::vector<std::string> kPoseColumns = {"t", "x", "y", "theta"};
const std::vector<std::string> kFixColumns = {"t", "x", "y"};
const std::vector<std::string> kTrueLandmarkColumns = {"id", "x", "y"};
const std::vector<std::string> kLandmarkColumns = {"id", "x", "y", "sxx", "sxy", "syy"};

// Calls visit(row, values) for each row of the CSV file `path`; nothing when it is absent.
// CsvReader throws "PATH:LINE: reason" for a malformed file.
template <class Visit>
void read_rows(const std::string& path, const std::vector<std::string>& columns, Visit&& visit) {
  std::error_code error;
  if (!std::filesystem::exists(path, error)) return;
  CsvReader reader(path, columns);
  double values[6];
  const std::span<double> row(values, columns.size());
  for (std::uint64_t i = 0; reader.next(row); ++i) visit(i, row);
}

// The rigid alignment metrics.json reports: rotation about the origin, then the shift.
struct Alignment {
  double c = 1, s = 0, x = 0, y = 0;
  Vertex operator()(const Vertex& v) const {
    return {c * v.x - s * v.y + x, s * v.x + c * v.y + y, v.segment};
  }
};

struct Zoom {
  Box window;  // a square
  std::vector<Vertex> truth, estimate;
  std::vector<Point> true_landmarks;
  std::vector<Estimate> landmarks;
  std::vector<std::pair<Point, Point>> links;  // an estimate, its true landmark
};

struct Run {
  nlohmann::json metrics = nlohmann::json::object();
  std::vector<Vertex> truth, estimate, aligned, dead_reckoning;
  std::vector<Point> gps, true_landmarks, landmarks;  // thinned to kMaxDots
  std::uint64_t gps_stride = 1, true_stride = 1, landmark_stride = 1;
  std::vector<Estimate> ellipses;  // the whole estimated map, when small enough
  Box extent;                      // of everything the main panel draws
  bool small = true;               // few landmarks: markers, a legend inside
  std::optional<Zoom> zoom;
};

nlohmann::json read_metrics(const std::string& path) {
  std::error_code error;
  if (!std::filesystem::exists(path, error)) return nlohmann::json::object();
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open for reading");
  nlohmann::json metrics;
  try {
    metrics = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw std::runtime_error(path + ": not valid JSON: " + e.what());
  }
  if (!metrics.is_object()) throw std::runtime_error(path + ": expected one JSON object");
  return metrics;
}

// metrics.json's pose_alignment, else its gps_alignment (rotation_deg, x_m, y_m); none when
// neither is there.
std::optional<Alignment> read_alignment(const nlohmann::json& metrics, const std::string& path) {
  for (const char* key : {"pose_alignment", "gps_alignment"}) {
    const auto found = metrics.find(key);
    if (found == metrics.end() || found->is_null() || found->empty()) continue;
    const nlohmann::json& a = *found;
    const auto number = [&](const char* name) {
      if (!a.is_object() || !a.contains(name) || !a[name].is_number()) {
        throw std::runtime_error(path + ": " + key +
                                 ": expected numbers rotation_deg, x_m and y_m");
      }
      return a[name].get<double>();
    };
    const double angle = number("rotation_deg") * std::numbers::pi / 180;
    return Alignment{std::cos(angle), std::sin(angle), number("x_m"), number("y_m")};
  }
  return std::nullopt;
}

// The four position files' rows read from `dir` (a path whose file is absent stays empty), for
// a picture the run handed none to.
PicturePaths read_paths(const std::string& dir) {
  PicturePaths paths;
  for (const auto& [name, columns, path] :
       {std::tuple{"/truth.csv", &kPoseColumns, &paths.truth},
        std::tuple{"/trajectory.csv", &kPoseColumns, &paths.estimate},
        std::tuple{"/dead_reckoning.csv", &kPoseColumns, &paths.dead_reckoning},
        std::tuple{"/gps.csv", &kFixColumns, &paths.gps}}) {
    PicturePath* into = path;  // clang 14 lambdas cannot capture a structured binding
    read_rows(dir + name, *columns,
              [into](std::uint64_t, std::span<const double> v) { into->add(v[1], v[2]); });
  }
  return paths;
}

std::vector<Vertex> vertices(const PicturePath& path) {
  std::vector<Vertex> out;
  for (const PicturePath::Point& p : path.rows().values(true)) out.push_back({p.x, p.y, 0});
  return out;
}

void add_box(Box& extent, const PicturePath& path) {
  const std::array<double, 4> b = path.box();
  extent.add(Box{b[0], b[1], b[2], b[3]});
}

Run read_run(const std::string& dir, const PicturePaths* paths) {
  Run run;
  const std::string metrics_path = dir + "/metrics.json";
  run.metrics = read_metrics(metrics_path);
  const std::optional<Alignment> alignment = read_alignment(run.metrics, metrics_path);

  // True landmarks: dots, extent, centroid.
  Thinned<Point> true_dots(kMaxDots);
  Box true_box;
  double sum_x = 0, sum_y = 0;
  read_rows(dir + "/true_landmarks.csv", kTrueLandmarkColumns,
            [&](std::uint64_t row, std::span<const double> v) {
              true_dots.add(row, {v[1], v[2]});
              true_box.add(v[1], v[2]);
              sum_x += v[1];
              sum_y += v[2];
            });
  const std::uint64_t true_count = true_dots.offered();
  run.true_landmarks = true_dots.values();
  run.true_stride = true_dots.stride();
  run.extent.add(true_box);

  // The paths and the fixes: the run's own rows, else the files'.
  std::optional<PicturePaths> read;
  if (paths == nullptr) paths = &read.emplace(read_paths(dir));
  const PicturePath& truth = paths->truth;
  const PicturePath& estimate = paths->estimate;
  const PicturePath& dead_reckoning = paths->dead_reckoning;
  const PicturePath& gps = paths->gps;
  run.truth = vertices(truth);
  run.estimate = vertices(estimate);
  run.dead_reckoning = vertices(dead_reckoning);
  for (const PicturePath::Point& p : gps.rows().values()) run.gps.push_back({p.x, p.y});
  run.gps_stride = gps.rows().stride();
  for (const PicturePath* path : {&truth, &estimate, &dead_reckoning, &gps}) {
    add_box(run.extent, *path);
  }
  if (alignment) {
    for (const Vertex& v : run.estimate) {
      run.aligned.push_back((*alignment)(v));
      run.extent.add(run.aligned.back().x, run.aligned.back().y);
    }
  }

  // A square holding about kZoomWindowLandmarks true landmarks at their mean density, centred
  // on the true path's drawn vertex nearest the landmarks' centroid; paths are read within half
  // its side around it, so that lines leave it at its edges.
  std::optional<Box> window;
  Box near;
  if (true_count > 0 && !run.truth.empty()) {
    const Point centroid = {sum_x / static_cast<double>(true_count),
                            sum_y / static_cast<double>(true_count)};
    Point nearest;
    double nearest_d2 = kInf;
    for (const Vertex& v : run.truth) {
      const double d2 =
          (v.x - centroid.x) * (v.x - centroid.x) + (v.y - centroid.y) * (v.y - centroid.y);
      if (d2 < nearest_d2) nearest_d2 = d2, nearest = {v.x, v.y};
    }
    const double area = std::max(1e-9, (true_box.x1 - true_box.x0) * (true_box.y1 - true_box.y0));
    const double half = 0.5 * std::sqrt(kZoomWindowLandmarks * area / true_count);
    window = Box{nearest.x - half, nearest.x + half, nearest.y - half, nearest.y + half};
    near = Box{window->x0 - half, window->x1 + half, window->y0 - half, window->y1 + half};
  }

  // The estimated map: dots, the first rows for the ellipses of a small map, and those in the
  // zoom window.
  Thinned<Point> dots(kMaxDots);
  Thinned<Estimate> in_window(kMaxDots);
  std::uint64_t in_window_count = 0;
  read_rows(dir + "/landmarks.csv", kLandmarkColumns,
            [&](std::uint64_t row, std::span<const double> v) {
              const Estimate e{v[0], v[1], v[2], v[3], v[4], v[5]};
              dots.add(row, {e.x, e.y});
              run.extent.add(e.x, e.y);
              if (row <= kMaxEllipseLandmarks) run.ellipses.push_back(e);
              if (window && window->contains(e.x, e.y)) in_window.add(in_window_count++, e);
            });
  const std::uint64_t landmark_count = dots.offered();
  run.landmarks = dots.values();
  run.landmark_stride = dots.stride();
  if (landmark_count > kMaxEllipseLandmarks) run.ellipses.clear();
  for (const Estimate& e : run.ellipses) {
    const double hx = 2 * std::sqrt(std::max(0.0, e.sxx)), hy = 2 * std::sqrt(std::max(0.0, e.syy));
    run.extent.add(e.x - hx, e.y - hy);
    run.extent.add(e.x + hx, e.y + hy);
  }

  run.small = landmark_count <= kZoomLandmarks && true_count <= kZoomLandmarks;
  if (run.small || !window) return run;
  Zoom& zoom = run.zoom.emplace();
  zoom.window = *window;
  zoom.landmarks = in_window.values();
  // Near the window at full resolution: a second pass over the two paths' files.
  for (const auto& [name, into] :
       {std::pair{"/truth.csv", &zoom.truth}, std::pair{"/trajectory.csv", &zoom.estimate}}) {
    NearPath near_path(near);
    read_rows(dir + name, kPoseColumns, [&](std::uint64_t row, std::span<const double> v) {
      near_path.offer(row, v[1], v[2]);
    });
    *into = near_path.values();
  }
  // Under known association each estimate in the window is joined to the true landmark of its
  // id, wherever that is.
  std::unordered_map<double, Point> true_of;
  if (run.metrics.value("association", nlohmann::json()) == "known") {
    for (const Estimate& e : zoom.landmarks) true_of.emplace(e.id, Point{kInf, kInf});
  }
  Thinned<Point> true_in_window(kMaxDots);
  std::uint64_t true_in_window_count = 0;
  read_rows(dir + "/true_landmarks.csv", kTrueLandmarkColumns,
            [&](std::uint64_t, std::span<const double> v) {
              if (window->contains(v[1], v[2]))
                true_in_window.add(true_in_window_count++, {v[1], v[2]});
              if (const auto found = true_of.find(v[0]); found != true_of.end()) {
                found->second = {v[1], v[2]};
              }
            });
  zoom.true_landmarks = true_in_window.values();
  for (const Estimate& e : zoom.landmarks) {
    const auto found = true_of.find(e.id);
    if (found != true_of.end() && found->second.x != kInf) {
      zoom.links.push_back({{e.x, e.y}, found->second});
    }
  }
  return run;
}

// How it is drawn. Lengths in px; matplotlib's sizes at its 110 dpi.

constexpr double kCharWidth = 0.56;  // of the font size, an average DejaVu Sans character
constexpr double kTitleSize = 14, kCaptionSize = 12.5, kTickSize = 12, kLabelSize = 13;
constexpr double kLegendSize = 12;

const char* const kBlack = "#000000";
const char* const kBlue = "#1f77b4";    // tab:blue
const char* const kRed = "#d62728";     // tab:red
const char* const kGreen = "#2ca02c";   // tab:green
const char* const kCyan = "#17becf";    // tab:cyan
const char* const kOrange = "#ff7f0e";  // tab:orange
const char* const kMagenta = "#bf00bf";
const char* const kDarkGrey = "#595959";
const char* const kGrey = "#8c8c8c";
const char* const kLightGrey = "#999999";

double text_width(std::string_view text, double size) {
  std::size_t chars = 0;
  for (const char c : text) chars += (static_cast<unsigned char>(c) & 0xc0) != 0x80;
  return static_cast<double>(chars) * size * kCharWidth;
}

// A plot area: data (metres, y up) at equal scale on both axes in the rectangle at (left, top).
struct Panel {
  double left = 0, top = 0, width = 0, height = 0;
  double x0 = 0, y1 = 0, scale = 1;

  double X(double x) const { return left + (x - x0) * scale; }
  double Y(double y) const { return top + (y1 - y) * scale; }
  double x1() const { return x0 + width / scale; }
  double y0() const { return y1 - height / scale; }
};

// The plot area for `extent` widened by `margin` of its size on each side (matplotlib's 5%),
// at most `size` px a side, in the data's aspect between 1:4 and 4:1 (the range widened
// beyond).
Panel fit(Box extent, double size, double margin) {
  if (extent.empty()) extent = Box{0, 1, 0, 1};
  // A single point or line gets a metre around it.
  const auto pad = [margin](double& lo, double& hi) {
    const double span = hi - lo;
    const double by = span > 1e-9 ? margin * span : 0.5;
    lo -= by;
    hi += by;
  };
  pad(extent.x0, extent.x1);
  pad(extent.y0, extent.y1);
  const double dx = extent.x1 - extent.x0, dy = extent.y1 - extent.y0;
  const double aspect = std::clamp(dy / dx, 0.25, 4.0);
  Panel p;
  p.width = aspect <= 1 ? size : size / aspect;
  p.height = aspect <= 1 ? size * aspect : size;
  p.scale = std::min(p.width / dx, p.height / dy);
  p.x0 = 0.5 * (extent.x0 + extent.x1) - 0.5 * p.width / p.scale;
  p.y1 = 0.5 * (extent.y0 + extent.y1) + 0.5 * p.height / p.scale;
  return p;
}

// Round-number ticks in [lo, hi], about `target` of them: steps of 1, 2, 2.5 or 5 times a
// power of ten; with the decimals their labels need.
struct Ticks {
  std::vector<double> values;
  int decimals = 0;
};
Ticks ticks(double lo, double hi, double target) {
  Ticks t;
  const double raw = (hi - lo) / std::max(1.0, target);
  if (!(raw > 0) || !std::isfinite(raw)) return t;
  const double magnitude = std::pow(10.0, std::floor(std::log10(raw)));
  double step = 10 * magnitude;
  for (const double m : {1.0, 2.0, 2.5, 5.0}) {
    if (m * magnitude >= raw * (1 - 1e-9)) {
      step = m * magnitude;
      break;
    }
  }
  while (t.decimals < 12) {
    const double scaled = step * std::pow(10.0, t.decimals);
    if (std::abs(scaled - std::round(scaled)) <= 1e-6 * scaled) break;
    ++t.decimals;
  }
  // Counted, not stepped: far from 0 (|lo / step| > 2^53) k + 1 would equal k.
  const double first = std::ceil(lo / step - 1e-9);
  const double count = std::floor(hi / step + 1e-9) - first + 1;
  for (int i = 0; i < std::min(count, 20.0); ++i) {
    const double k = first + i;
    t.values.push_back(std::abs(k) < 0.5 ? 0.0 : k * step);
  }
  return t;
}

std::string tick_label(double v, int decimals) {
  TextLine t;
  t.fixed(v, decimals);
  return std::string(t.view());
}

// Hundredths of a pixel, clamped far outside any picture.
long long centi(double px) { return std::llround(std::clamp(px, -1e7, 1e7) * 100); }

// `c` hundredths of a pixel, no trailing zeros: 12.5, 3, -0.07. Built backwards in a buffer
// and appended once: a path has a few numbers per vertex and up to kMaxPathPoints vertices.
void put_centi(TextLine& t, long long c) {
  char buf[24];
  char* p = buf + sizeof(buf);
  std::uint64_t u = c < 0 ? 0 - static_cast<std::uint64_t>(c) : static_cast<std::uint64_t>(c);
  const unsigned f = static_cast<unsigned>(u % 100);
  u /= 100;
  if (f != 0) {
    if (f % 10 != 0) *--p = static_cast<char>('0' + f % 10);
    *--p = static_cast<char>('0' + f / 10);
    *--p = '.';
  }
  do {
    *--p = static_cast<char>('0' + u % 10);
    u /= 10;
  } while (u != 0);
  if (c < 0) *--p = '-';
  t.text(std::string_view(p, static_cast<std::size_t>(buf + sizeof(buf) - p)));
}

void put_px(TextLine& t, double px) { put_centi(t, centi(px)); }

// A path's d attribute in relative moves counted in hundredths of a pixel, so that rounding
// does not accumulate: "m" then implicit line pairs; dots as "m.. h0" with round caps.
class PathData {
 public:
  explicit PathData(TextLine& t) : t_(t) {}

  void move_to(double X, double Y) {
    command('m');
    to(centi(X), centi(Y));
  }
  // A line from the current point; a repeated point is left out.
  void line_to(double X, double Y) {
    const long long x = centi(X), y = centi(Y);
    if (x == x_ && y == y_) return;
    if (last_ != 'm' && last_ != 'l') command('l');
    to(x, y);
  }
  // A zero-length stroke: with round caps, a dot of the stroke's width.
  void dot(double X, double Y) {
    const long long x = centi(X), y = centi(Y);
    if (x == x_ && y == y_ && last_ == 'h') return;
    command('m');
    to(x, y);
    command('h');
    number(0);
  }
  // A "+" of arms `arm` px.
  void plus(double X, double Y, double arm) {
    const long long x = centi(X), y = centi(Y), r = centi(arm);
    command('m');
    to(x - r, y);
    command('h');
    number(2 * r);
    x_ += 2 * r;
    command('m');
    to(x, y - r);
    command('v');
    number(2 * r);
    y_ += 2 * r;
  }

 private:
  void command(char c) {
    t_.put(c);
    last_ = c;
    separate_ = false;
  }
  // A minus sign separates numbers by itself.
  void number(long long c) {
    if (separate_ && c >= 0) t_.put(' ');
    put_centi(t_, c);
    separate_ = true;
  }
  void to(long long x, long long y) {
    number(x - x_);
    number(y - y_);
    x_ = x;
    y_ = y;
  }

  TextLine& t_;
  long long x_ = 0, y_ = 0;  // the current point
  char last_ = 0;
  bool separate_ = false;
};

// How a series looks, in the picture and in the legend.
struct Style {
  enum Kind { kLine, kDot, kPlus, kRectangle } kind = kLine;
  const char* colour = kBlack;
  double width = 1.2;  // a line's or a "+"'s stroke; a dot's diameter
  const char* dash = nullptr;
  double arm = 0;  // a "+"'s half size
};

struct LegendEntry {
  std::string label;
  Style style;
};

std::string shown(std::string label, std::uint64_t stride) {
  if (stride > 1) label += " (1 in " + std::to_string(stride) + " shown)";
  return label;
}

// The SVG text, handed to the file in blocks of about 64 KiB.
class Svg {
 public:
  explicit Svg(AtomicFile& file) : file_(file) {}
  ~Svg() = default;
  Svg(const Svg&) = delete;
  Svg& operator=(const Svg&) = delete;

  TextLine& t() { return t_; }
  Svg& s(std::string_view text) {
    t_.text(text);
    return *this;
  }
  Svg& px(double v) {
    put_px(t_, v);
    return *this;
  }
  // `name`="px"
  Svg& attr(std::string_view name, double v) {
    t_.put(' ').text(name).text("=\"");
    put_px(t_, v);
    t_.put('"');
    return *this;
  }
  Svg& escaped(std::string_view text) {
    for (const char c : text) {
      switch (c) {
        case '&':
          t_.text("&amp;");
          break;
        case '<':
          t_.text("&lt;");
          break;
        case '>':
          t_.text("&gt;");
          break;
        case '"':
          t_.text("&quot;");
          break;
        default:
          t_.put(c);
      }
    }
    return *this;
  }
  // <text x y attrs>TEXT</text>
  void text(double x, double y, std::string_view attrs, std::string_view text) {
    s("<text").attr("x", x).attr("y", y);
    if (!attrs.empty()) s(" ").s(attrs);
    s(">").escaped(text).s("</text>\n");
    flush(false);
  }
  void flush(bool all) {
    if (!all && t_.view().size() < (std::size_t{1} << 16)) return;
    file_.write(t_.view());
    t_.clear();
  }

 private:
  AtomicFile& file_;
  TextLine t_;
};

// The stroke attributes of a style.
void stroke(Svg& svg, const Style& style) {
  svg.s(" fill=\"none\" stroke=\"").s(style.colour).s("\"");
  svg.attr("stroke-width", style.width);
  if (style.kind == Style::kDot) svg.s(" stroke-linecap=\"round\"");
  if (style.dash != nullptr) svg.s(" stroke-dasharray=\"").s(style.dash).s("\"");
}

// One <path> element of `count` pieces in `style`: draw(d, i) adds piece i to its data.
template <class Draw>
void styled_path(Svg& svg, const char* id, std::size_t count, const Style& style, Draw&& draw) {
  if (count == 0) return;
  svg.s("<path id=\"").s(id).s("\"");
  stroke(svg, style);
  svg.s(" d=\"");
  PathData d(svg.t());
  for (std::size_t i = 0; i < count; ++i) {
    draw(d, i);
    if (i % 1024 == 0) svg.flush(false);
  }
  svg.s("\"/>\n");
}

void polyline(Svg& svg, const char* id, const std::vector<Vertex>& path, const Style& style,
              const Panel& p) {
  styled_path(svg, id, path.size(), style, [&](PathData& d, std::size_t i) {
    if (i == 0 || path[i].segment != path[i - 1].segment) {
      d.move_to(p.X(path[i].x), p.Y(path[i].y));
    } else {
      d.line_to(p.X(path[i].x), p.Y(path[i].y));
    }
  });
}

void markers(Svg& svg, const char* id, const std::vector<Point>& points, const Style& style,
             const Panel& p) {
  styled_path(svg, id, points.size(), style, [&](PathData& d, std::size_t i) {
    if (style.kind == Style::kPlus) {
      d.plus(p.X(points[i].x), p.Y(points[i].y), style.arm);
    } else {
      d.dot(p.X(points[i].x), p.Y(points[i].y));
    }
  });
}

// The 2-sigma ellipse of each estimate (plot_run.py's `ellipse`); y is down in the picture, so
// the angle turns the other way.
void ellipses(Svg& svg, const char* id, const std::vector<Estimate>& estimates, const Panel& p) {
  if (estimates.empty()) return;
  svg.s("<g id=\"").s(id).s("\" fill=\"none\" stroke=\"").s(kRed).s("\" stroke-width=\"0.9\">\n");
  for (const Estimate& e : estimates) {
    const double a = e.sxx, b = e.sxy, c = e.syy;
    const double t = std::sqrt(std::max(0.0, (a - c) * (a - c) / 4 + b * b));
    const double l1 = std::max(0.0, (a + c) / 2 + t), l2 = std::max(0.0, (a + c) / 2 - t);
    const double angle = 0.5 * std::atan2(2 * b, a - c) * 180 / std::numbers::pi;
    const double x = p.X(e.x), y = p.Y(e.y);
    svg.s("<ellipse").attr("cx", x).attr("cy", y);
    svg.attr("rx", 2 * std::sqrt(l1) * p.scale).attr("ry", 2 * std::sqrt(l2) * p.scale);
    if (std::abs(angle) >= 0.05) {
      svg.s(" transform=\"rotate(");
      svg.t().fixed(-angle, 1);
      svg.s(" ").px(x).s(" ").px(y).s(")\"");
    }
    svg.s("/>\n");
    svg.flush(false);
  }
  svg.s("</g>\n");
}

void links(Svg& svg, const std::vector<std::pair<Point, Point>>& pairs, const Panel& p) {
  if (pairs.empty()) return;
  svg.s("<path id=\"zoom-links\"");
  stroke(svg, {Style::kLine, kOrange, 1.0});
  svg.s(" d=\"");
  PathData d(svg.t());
  for (const auto& [from, to] : pairs) {
    d.move_to(p.X(from.x), p.Y(from.y));
    d.line_to(p.X(to.x), p.Y(to.y));
  }
  svg.s("\"/>\n");
}

// A legend's size and where its entries go: one column inside a panel, up to three below.
struct Legend {
  std::vector<LegendEntry> entries;
  std::size_t columns = 1, rows = 0;
  std::vector<double> column_widths;
  double width = 0, height = 0;

  static constexpr double kRow = 18, kPad = 7, kSymbol = 30, kGap = 6;

  Legend(std::vector<LegendEntry> e, std::size_t max_columns) : entries(std::move(e)) {
    if (entries.empty()) return;
    columns = std::min(max_columns, entries.size());
    rows = (entries.size() + columns - 1) / columns;
    columns = (entries.size() + rows - 1) / rows;
    column_widths.assign(columns, 0);
    for (std::size_t i = 0; i < entries.size(); ++i) {
      double& w = column_widths[i / rows];
      w = std::max(w, kSymbol + kGap + text_width(entries[i].label, kLegendSize) + 14);
    }
    width = 2 * kPad - 14;
    for (const double w : column_widths) width += w;
    height = 2 * kPad + kRow * static_cast<double>(rows);
  }

  // Column-major, as matplotlib fills its columns.
  void draw(Svg& svg, const char* id, double left, double top) const {
    if (entries.empty()) return;
    svg.s("<g id=\"").s(id).s("\" font-size=\"").px(kLegendSize).s("\">\n");
    svg.s("<rect").attr("x", left).attr("y", top).attr("width", width).attr("height", height);
    svg.s(" rx=\"3\" fill=\"#ffffff\" fill-opacity=\"0.85\" stroke=\"#cccccc\"/>\n");
    double column_left = left + kPad;
    for (std::size_t c = 0; c < columns; ++c) {
      for (std::size_t r = 0; r < rows && c * rows + r < entries.size(); ++r) {
        const LegendEntry& e = entries[c * rows + r];
        const double y = top + kPad + kRow * (static_cast<double>(r) + 0.5);
        const double x = column_left;
        const Style& s = e.style;
        if (s.kind == Style::kLine) {
          svg.s("<path");
          stroke(svg, s);
          svg.s(" d=\"M").px(x).s(" ").px(y).s("h").px(kSymbol).s("\"/>\n");
        } else if (s.kind == Style::kRectangle) {
          svg.s("<rect").attr("x", x + 6).attr("y", y - 5).attr("width", kSymbol - 12);
          svg.attr("height", 10);
          stroke(svg, s);
          svg.s("/>\n");
        } else {
          Style big = s;
          big.width = s.kind == Style::kDot ? std::max(s.width, 6.0) : s.width;
          big.arm = std::max(s.arm, 4.0);
          svg.s("<path");
          stroke(svg, big);
          svg.s(" d=\"");
          PathData d(svg.t());
          if (s.kind == Style::kDot) {
            d.dot(x + kSymbol / 2, y);
          } else {
            d.plus(x + kSymbol / 2, y, big.arm);
          }
          svg.s("\"/>\n");
        }
        svg.text(x + kSymbol + kGap, y, "dy=\"0.35em\"", e.label);
      }
      column_left += column_widths[c];
    }
    svg.s("</g>\n");
  }
};

// matplotlib's loc="best", simplified: the corner or edge middle of the panel (in its order of
// preference) over which the fewest of the drawn points fall.
std::pair<double, double> best_place(const Legend& legend, const Panel& p,
                                     const std::vector<const std::vector<Vertex>*>& paths,
                                     const std::vector<const std::vector<Point>*>& dots) {
  constexpr double kInset = 8;
  const double left = p.left + kInset, right = p.left + p.width - kInset - legend.width;
  const double top = p.top + kInset, bottom = p.top + p.height - kInset - legend.height;
  const double middle_x = p.left + 0.5 * (p.width - legend.width);
  const double middle_y = p.top + 0.5 * (p.height - legend.height);
  const std::pair<double, double> places[] = {
      {right, top},      {left, top},      {left, bottom},     {right, bottom},
      {right, middle_y}, {left, middle_y}, {middle_x, bottom}, {middle_x, top}};
  std::pair<double, double> best = places[0];
  std::size_t fewest = std::numeric_limits<std::size_t>::max();
  for (const auto& [x, y] : places) {
    const Box box{x, x + legend.width, y, y + legend.height};
    std::size_t count = 0;
    for (const auto* path : paths) {
      for (const Vertex& v : *path) count += box.contains(p.X(v.x), p.Y(v.y));
    }
    for (const auto* set : dots) {
      for (const Point& v : *set) count += box.contains(p.X(v.x), p.Y(v.y));
    }
    if (count < fewest) fewest = count, best = {x, y};
  }
  return best;
}

// A panel's frame, grid, ticks and axis labels; the data goes between open() and close().
struct Axes {
  Panel panel;
  Ticks x_ticks, y_ticks;
  double y_label_width = 0;  // the widest y tick label

  explicit Axes(const Panel& p) : panel(p) {
    // matplotlib's MaxNLocator: at most 9 intervals, fewer on a small axis.
    x_ticks = ticks(p.x0, p.x1(), std::clamp(p.width / 50, 3.0, 9.0));
    y_ticks = ticks(p.y0(), p.y1, std::clamp(p.height / 50, 3.0, 9.0));
    for (const double v : y_ticks.values) {
      y_label_width =
          std::max(y_label_width, text_width(tick_label(v, y_ticks.decimals), kTickSize));
    }
  }
  double margin_left() const { return 8 + kLabelSize + 10 + y_label_width + 8; }
  double column_left = 0, column_width = 0;  // the panel's share of the width, with its labels
  static constexpr double kMarginBottom = 48;

  void open(Svg& svg, const char* id) const {
    const Panel& p = panel;
    svg.s("<g id=\"").s(id).s("\">\n<clipPath id=\"").s(id).s("-clip\"><rect");
    svg.attr("x", p.left).attr("y", p.top).attr("width", p.width).attr("height", p.height);
    svg.s(
        "/></clipPath>\n<path class=\"grid\" fill=\"none\" stroke=\"#dddddd\" stroke-width=\"0.8\" "
        "d=\"");
    for (const double v : x_ticks.values)
      svg.s("M").px(p.X(v)).s(" ").px(p.top).s("V").px(p.top + p.height);
    for (const double v : y_ticks.values)
      svg.s("M").px(p.left).s(" ").px(p.Y(v)).s("H").px(p.left + p.width);
    svg.s("\"/>\n<g clip-path=\"url(#").s(id).s("-clip)\">\n");
  }

  void close(Svg& svg) const {
    const Panel& p = panel;
    const double bottom = p.top + p.height;
    svg.s("</g>\n<rect fill=\"none\" stroke=\"#000000\" stroke-width=\"1\"");
    svg.attr("x", p.left).attr("y", p.top).attr("width", p.width).attr("height", p.height);
    svg.s("/>\n<path stroke=\"#000000\" stroke-width=\"1\" d=\"");
    for (const double v : x_ticks.values) svg.s("M").px(p.X(v)).s(" ").px(bottom).s("v5");
    for (const double v : y_ticks.values) svg.s("M").px(p.left).s(" ").px(p.Y(v)).s("h-5");
    svg.s("\"/>\n<g font-size=\"").px(kTickSize).s("\" text-anchor=\"middle\">\n");
    for (const double v : x_ticks.values) {
      svg.text(p.X(v), bottom + 8 + kTickSize, "class=\"x-tick\"", tick_label(v, x_ticks.decimals));
    }
    svg.s("</g>\n<g font-size=\"").px(kTickSize).s("\" text-anchor=\"end\">\n");
    for (const double v : y_ticks.values) {
      svg.text(p.left - 8, p.Y(v), "class=\"y-tick\" dy=\"0.35em\"",
               tick_label(v, y_ticks.decimals));
    }
    svg.s("</g>\n<g font-size=\"").px(kLabelSize).s("\" text-anchor=\"middle\">\n");
    svg.text(p.left + p.width / 2, bottom + 8 + kTickSize + 8 + kLabelSize, "", "x (m)");
    const double x = p.left - 18 - y_label_width, y = p.top + p.height / 2;
    svg.s("<text").attr("x", x).attr("y", y).s(" transform=\"rotate(-90 ").px(x).s(" ").px(y);
    svg.s(")\">y (m)</text>\n</g>\n</g>\n");
  }
};

// plot_run.py's title: the run's settings, then its errors.
std::vector<std::string> title_lines(const nlohmann::json& m) {
  if (m.empty()) return {"fastslam run"};
  const auto word = [&](const char* key) {
    const auto found = m.find(key);
    if (found == m.end() || found->is_null()) return std::string("?");
    return found->is_string() ? found->get<std::string>() : found->dump();
  };
  const auto number = [](const nlohmann::json& j, const char* key) -> std::optional<double> {
    const auto found = j.find(key);
    if (found == j.end() || !found->is_number()) return std::nullopt;
    return found->get<double>();
  };
  std::string errors;
  const auto add = [&](const std::string& name, double v) {
    TextLine t;
    t.text(errors.empty() ? "" : ", ").text(name).put(' ').fixed(v, 2).text(" m");
    errors += t.view();
  };
  const std::pair<const char*, const char*> kErrors[] = {
      {"pose_rmse_m", "pose RMSE"}, {"pose_rmse_aligned_m", "aligned"},
      {"gps_rmse_m", "GPS RMSE"},   {"gps_rmse_aligned_m", "aligned"},
      {"gospa_m", "map GOSPA"},     {"landmark_rmse_m", "landmark RMSE"}};
  for (const auto& [key, name] : kErrors) {
    if (const auto v = number(m, key)) add(name, *v);
  }
  if (const auto found = m.find("dead_reckoning"); found != m.end() && found->is_object()) {
    for (const char* key : {"pose_rmse_m", "gps_rmse_m"}) {
      const auto baseline = number(*found, key);
      if (baseline && number(m, key)) {
        add("dead reckoning", *baseline);
        break;
      }
    }
  }
  std::string head = word("algorithm") + " M=" + word("particles") + " " + word("association") +
                     " association, seed " + word("seed");
  const auto true_landmarks = number(m, "true_landmarks");
  if (true_landmarks && *true_landmarks != 0) {
    head += ", " + word("true_landmarks") + " landmarks";
  } else if (m.contains("landmarks")) {
    head += ", " + word("landmarks") + " landmarks mapped";
  }
  if (m.contains("steps")) head += ", " + word("steps") + " steps";
  if (m.value("motion", nlohmann::json()) == "none") head += ", no odometry";
  if (errors.empty()) return {head};
  return {head + ":", errors};
}

void draw(const Run& run, AtomicFile& file) {
  const std::vector<std::string> title = title_lines(run.metrics);
  const bool two = run.zoom.has_value();

  // The main panel's series, in plot_run.py's order (landmarks under the paths) and styles.
  const bool small = run.small;
  const Style true_style =
      small ? Style{Style::kPlus, kDarkGrey, 1.1, nullptr, 3.3} : Style{Style::kDot, kGrey, 1.3};
  const Style map_style = small ? Style{Style::kDot, kRed, 4.5} : Style{Style::kDot, kRed, 1.3};
  const Style truth_style{Style::kLine, kBlack, 1.2};
  const Style gps_style{Style::kDot, kGreen, 2.2};
  const Style dr_style{Style::kLine, kLightGrey, 1.1, "4.5 2"};
  const Style estimate_style{Style::kLine, kBlue, 1.2};
  const Style aligned_style{Style::kLine, kCyan, 1.2, "7 2 1.5 2"};
  const Style window_style{Style::kRectangle, kMagenta, 1.8};

  std::vector<LegendEntry> entries;
  if (!run.true_landmarks.empty()) {
    entries.push_back({shown("true landmarks", run.true_stride), true_style});
  }
  if (!run.landmarks.empty()) {
    entries.push_back(
        {shown(run.ellipses.empty() ? "estimated map (best particle)"
                                    : "estimated map (best particle), 2-sigma ellipses",
               run.landmark_stride),
         map_style});
  }
  if (!run.truth.empty()) entries.push_back({"true path", truth_style});
  if (!run.gps.empty()) entries.push_back({shown("GPS fixes", run.gps_stride), gps_style});
  if (!run.dead_reckoning.empty()) entries.push_back({"dead reckoning", dr_style});
  if (!run.estimate.empty()) {
    entries.push_back({"estimated path (weighted mean)", estimate_style});
  }
  if (!run.aligned.empty()) entries.push_back({"estimated path, rigidly aligned", aligned_style});
  if (two) entries.push_back({"zoomed window", window_style});
  Panel main = fit(run.extent, two ? 760 : 880, 0.05);
  // Inside the panel for a small map, as matplotlib's loc="best", unless it does not fit
  // there; below it in up to three columns otherwise.
  const Legend inside(entries, 1);
  const bool legend_below =
      !run.small || inside.width > main.width - 16 || inside.height > main.height - 16;
  const Legend legend = legend_below ? Legend(entries, 3) : inside;
  std::optional<Panel> zoom_panel;
  std::optional<Legend> zoom_legend;
  std::vector<std::string> caption;
  if (two) {
    const Zoom& z = *run.zoom;
    zoom_panel = fit(z.window, 760, 0);
    std::vector<LegendEntry> e = {
        {"true landmarks", {Style::kPlus, kDarkGrey, 1.1, nullptr, 3.3}},
        {"estimated map (best particle), 2-sigma ellipses", {Style::kDot, kRed, 4.5}},
        {"true path", truth_style},
        {"estimated path (weighted mean)", estimate_style}};
    if (!z.links.empty())
      e.push_back({"estimate to its true landmark", {Style::kLine, kOrange, 1.0}});
    zoom_legend.emplace(std::move(e), 3);
    TextLine t;
    const double side = z.window.x1 - z.window.x0;
    t.text("zoom: ").fixed(side, 0).text(" m x ").fixed(side, 0);
    t.text(" m on the true path near the middle of the map");
    caption.emplace_back(t.view());
    caption.emplace_back(z.links.empty() ? "(estimate ellipses 2 sigma)"
                                         : "(estimate ellipses 2 sigma; orange: estimate to its "
                                           "true landmark)");
  }

  // Layout: the title across the top, the panels side by side under it, each with its legend
  // below when the map is large.
  const double title_height = 12 + 19 * static_cast<double>(title.size());
  const double caption_height = caption.empty() ? 0 : 4 + 17 * static_cast<double>(caption.size());
  const double top = title_height + caption_height + 8;
  Axes main_axes(main);
  std::optional<Axes> zoom_axes;
  if (zoom_panel) zoom_axes.emplace(*zoom_panel);
  double x = 0;
  const auto place = [&](Axes& axes, const Legend* below) {
    const double needed = axes.margin_left() + axes.panel.width + 20;
    const double outer = std::max(needed, below != nullptr ? below->width + 20 : 0.0);
    axes.panel.left = x + axes.margin_left() + 0.5 * (outer - needed);
    axes.panel.top = top;
    axes.column_left = x;
    axes.column_width = outer;
    x += outer;
  };
  place(main_axes, legend_below ? &legend : nullptr);
  if (zoom_axes) place(*zoom_axes, &*zoom_legend);
  double title_width = 0;
  for (const std::string& line : title) {
    title_width = std::max(title_width, text_width(line, kTitleSize));
  }
  const double width = std::ceil(std::max(x, title_width + 30));
  // Everything centred when the title is the widest.
  const double shift = 0.5 * (width - x);
  for (Axes* a : {&main_axes, zoom_axes ? &*zoom_axes : nullptr}) {
    if (a == nullptr) continue;
    a->panel.left += shift;
    a->column_left += shift;
  }
  double height = 0;
  for (const Axes* a : {&main_axes, zoom_axes ? &*zoom_axes : nullptr}) {
    if (a == nullptr) continue;
    const Legend& below = a == &main_axes ? legend : *zoom_legend;
    const bool has_below = a != &main_axes || legend_below;
    height = std::max(height, a->panel.top + a->panel.height + Axes::kMarginBottom +
                                  (has_below && !below.entries.empty() ? below.height + 8 : 0));
  }
  height = std::ceil(height + 6);

  AtomicFile& out = file;
  Svg svg(out);
  svg.s("<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<svg xmlns=\"http://www.w3.org/2000/svg\"");
  svg.attr("width", width).attr("height", height);
  svg.s(" viewBox=\"0 0 ").px(width).s(" ").px(height).s("\"");
  svg.s(" font-family=\"DejaVu Sans, Helvetica, Arial, sans-serif\" stroke-linejoin=\"round\">\n");
  svg.s("<title>");
  for (std::size_t i = 0; i < title.size(); ++i) svg.s(i == 0 ? "" : " ").escaped(title[i]);
  svg.s("</title>\n<rect width=\"100%\" height=\"100%\" fill=\"#ffffff\"/>\n");
  svg.s("<g id=\"title\" font-size=\"").px(kTitleSize).s("\" text-anchor=\"middle\">\n");
  for (std::size_t i = 0; i < title.size(); ++i) {
    svg.text(width / 2, 8 + 19 * static_cast<double>(i + 1) - 4, "", title[i]);
  }
  svg.s("</g>\n");

  const Panel& p = main_axes.panel;
  main_axes.open(svg, "map");
  markers(svg, "true-landmarks", run.true_landmarks, true_style, p);
  markers(svg, "landmarks", run.landmarks, map_style, p);
  ellipses(svg, "ellipses", run.ellipses, p);
  polyline(svg, "true-path", run.truth, truth_style, p);
  markers(svg, "gps", run.gps, gps_style, p);
  polyline(svg, "dead-reckoning", run.dead_reckoning, dr_style, p);
  polyline(svg, "estimated-path", run.estimate, estimate_style, p);
  polyline(svg, "aligned-path", run.aligned, aligned_style, p);
  if (two) {
    const Box& w = run.zoom->window;
    svg.s("<rect id=\"zoomed-window\"");
    stroke(svg, window_style);
    svg.attr("x", p.X(w.x0)).attr("y", p.Y(w.y1));
    svg.attr("width", (w.x1 - w.x0) * p.scale).attr("height", (w.y1 - w.y0) * p.scale);
    svg.s("/>\n");
  }
  main_axes.close(svg);
  if (legend_below) {
    legend.draw(svg, "legend",
                main_axes.column_left + 0.5 * (main_axes.column_width - legend.width),
                p.top + p.height + Axes::kMarginBottom);
  } else if (!legend.entries.empty()) {
    const auto [lx, ly] =
        best_place(legend, p, {&run.truth, &run.estimate, &run.aligned, &run.dead_reckoning},
                   {&run.true_landmarks, &run.landmarks, &run.gps});
    legend.draw(svg, "legend", lx, ly);
  }

  if (two) {
    const Zoom& z = *run.zoom;
    const Panel& q = zoom_axes->panel;
    svg.s("<g id=\"zoom-caption\" font-size=\"").px(kCaptionSize).s("\" text-anchor=\"middle\">\n");
    for (std::size_t i = 0; i < caption.size(); ++i) {
      svg.text(q.left + q.width / 2, title_height + 4 + 17 * static_cast<double>(i + 1) - 4, "",
               caption[i]);
    }
    svg.s("</g>\n");
    zoom_axes->open(svg, "zoom");
    links(svg, z.links, q);
    markers(svg, "zoom-true-landmarks", z.true_landmarks,
            {Style::kPlus, kDarkGrey, 1.1, nullptr, 3.3}, q);
    std::vector<Point> centres;
    for (const Estimate& e : z.landmarks) centres.push_back({e.x, e.y});
    markers(svg, "zoom-landmarks", centres, {Style::kDot, kRed, 4.5}, q);
    ellipses(svg, "zoom-ellipses", z.landmarks, q);
    polyline(svg, "zoom-true-path", z.truth, truth_style, q);
    polyline(svg, "zoom-estimated-path", z.estimate, estimate_style, q);
    zoom_axes->close(svg);
    zoom_legend->draw(svg, "zoom-legend",
                      zoom_axes->column_left + 0.5 * (zoom_axes->column_width - zoom_legend->width),
                      q.top + q.height + Axes::kMarginBottom);
  }
  svg.s("</svg>\n");
  svg.flush(true);
}

}  // namespace

void write_map_svg(const std::string& dir, const PicturePaths* paths) {
  const Run run = read_run(dir, paths);
  AtomicFile file(dir + "/map.svg");
  draw(run, file);
  file.commit();
}

}  // namespace fastslam::tools
