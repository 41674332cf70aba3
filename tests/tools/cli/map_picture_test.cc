#include "tools/cli/map_picture.h"

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "tests/tools/temp_path.h"
#include "tools/io/number_text.h"

namespace fastslam::tools {
namespace {

struct Xy {
  double x = 0, y = 0;
};

// What a path's d attribute draws, read back from the relative moves map_picture writes:
// the vertices of its lines, the dots (zero-length "h0" strokes) and the subpaths.
struct Drawn {
  std::vector<Xy> vertices, dots;
  std::size_t subpaths = 0;
};

Drawn decode(const std::string& d) {
  Drawn out;
  Xy at;
  char command = 0;
  std::size_t i = 0;
  const auto number = [&] {
    std::size_t used = 0;
    const double v = std::stod(d.substr(i), &used);
    i += used;
    return v;
  };
  while (i < d.size()) {
    const char c = d[i];
    if (c == ' ') {
      ++i;
      continue;
    }
    if (std::isalpha(static_cast<unsigned char>(c)) != 0) {
      command = c;
      ++i;
      if (command == 'm') ++out.subpaths;
    }
    if (command == 'm' || command == 'l') {
      at.x += number();
      at.y += number();
      out.vertices.push_back(at);
      if (command == 'm') command = 'l';  // pairs after a move are lines
    } else if (command == 'h') {
      const double dx = number();
      if (dx == 0) out.dots.push_back(at);
      at.x += dx;
    } else if (command == 'v') {
      at.y += number();
    } else {
      ADD_FAILURE() << "unexpected command '" << command << "' in " << d.substr(0, 80);
      break;
    }
  }
  return out;
}

class MapPicture : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = testing::temp_path("map_picture");
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override { std::filesystem::remove_all(dir_); }

  void write(const std::string& name, const std::string& text) {
    std::ofstream(dir_ + "/" + name) << text;
  }
  // A path file of `n` poses along a circle of radius r.
  void write_path(const std::string& name, std::size_t n, double r) {
    std::ofstream out(dir_ + "/" + name);
    out << "t,x,y,theta\n";
    TextLine line;
    for (std::size_t i = 0; i < n; ++i) {
      const double a = 2 * M_PI * static_cast<double>(i) / static_cast<double>(n);
      line.clear();
      line.fixed(0.025 * static_cast<double>(i), 3).put(',').fixed(r * std::cos(a), 6).put(',');
      line.fixed(r * std::sin(a), 6).text(",0\n");
      out << line.view();
    }
  }
  // `n` landmarks on a grid of spacing 1 m; estimates with a covariance of 0.01 I.
  void write_landmarks(const std::string& name, std::size_t n, bool estimated) {
    std::ofstream out(dir_ + "/" + name);
    out << (estimated ? "id,x,y,sxx,sxy,syy\n" : "id,x,y\n");
    const std::size_t side = static_cast<std::size_t>(std::ceil(std::sqrt(n)));
    for (std::size_t i = 0; i < n; ++i) {
      out << i << ',' << static_cast<double>(i % side) << ',' << static_cast<double>(i / side);
      out << (estimated ? ",0.01,0,0.01\n" : "\n");
    }
  }
  std::string draw() {
    write_map_svg(dir_);
    std::ifstream in(dir_ + "/map.svg");
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
  }
  // The d attribute of the element with `id`; empty when there is none.
  // (Found by hand: std::regex recurses per character and overflows the stack on a long d.)
  static std::string path_of(const std::string& svg, const std::string& id) {
    const std::size_t at = svg.find("id=\"" + id + "\"");
    if (at == std::string::npos) return "";
    const std::size_t end = svg.find('>', at);
    const std::size_t d = svg.find(" d=\"", at);
    if (d == std::string::npos || d > end) return "";
    return svg.substr(d + 4, svg.find('"', d + 4) - (d + 4));
  }
  static std::size_t count(const std::string& svg, const std::string& what) {
    std::size_t n = 0;
    for (std::size_t at = svg.find(what); at != std::string::npos; at = svg.find(what, at + 1)) {
      ++n;
    }
    return n;
  }
  // Tick label -> its position along the axis (x of an x tick, y of a y tick).
  static std::map<std::string, double> ticks(const std::string& svg, const std::string& axis) {
    std::map<std::string, double> out;
    const std::regex tick("<text x=\"([-0-9.]+)\" y=\"([-0-9.]+)\" class=\"" + axis +
                          "-tick\"[^>]*>([^<]*)</text>");
    for (auto it = std::sregex_iterator(svg.begin(), svg.end(), tick); it != std::sregex_iterator();
         ++it) {
      out[(*it)[3]] = std::stod((*it)[axis == "x" ? 1 : 2]);
    }
    return out;
  }
  std::string error() {
    try {
      write_map_svg(dir_);
    } catch (const std::runtime_error& e) {
      return e.what();
    }
    return "(no error)";
  }
  std::string dir_;
};

// Every series of a small run, its title and legend, in a file an XML parser reads.
TEST_F(MapPicture, DrawsEverySeriesOfARunAsWellFormedSvg) {
  write_path("truth.csv", 500, 40);
  write_path("trajectory.csv", 500, 41);
  write_path("dead_reckoning.csv", 500, 45);
  write("gps.csv", "t,x,y\n1,40,0\n2,0,40\n");
  write_landmarks("true_landmarks.csv", 30, false);
  write_landmarks("landmarks.csv", 25, true);
  write("metrics.json", R"({"algorithm": "fastslam1", "particles": 10, "association": "known",
      "seed": 3, "true_landmarks": 30, "steps": 500, "pose_rmse_m": 1.234, "gospa_m": 2.5,
      "dead_reckoning": {"pose_rmse_m": 7.5},
      "pose_alignment": {"rotation_deg": 90, "x_m": 1, "y_m": 2}})");
  const std::string svg = draw();
  for (const char* id : {"true-path", "estimated-path", "aligned-path", "dead-reckoning", "gps",
                         "true-landmarks", "landmarks"}) {
    EXPECT_FALSE(path_of(svg, id).empty()) << id;
  }
  EXPECT_EQ(count(svg, "<ellipse"), 25u);
  EXPECT_NE(svg.find(">fastslam1 M=10 known association, seed 3, 30 landmarks, 500 steps:</text>"),
            std::string::npos);
  EXPECT_NE(svg.find(">pose RMSE 1.23 m, map GOSPA 2.50 m, dead reckoning 7.50 m</text>"),
            std::string::npos);
  for (const char* label : {">true landmarks<", ">true path<", ">GPS fixes<", ">dead reckoning<",
                            ">estimated path (weighted mean)<", ">estimated path, rigidly aligned<",
                            ">estimated map (best particle), 2-sigma ellipses<"}) {
    EXPECT_NE(svg.find(label), std::string::npos) << label;
  }
  EXPECT_EQ(svg.find("zoom"), std::string::npos);  // a small map: one panel

  // The aligned path is the estimate turned by 90 degrees and shifted by (1, 2): its first
  // vertex, the estimate's (41, 0), lands at (1, 43).
  const std::map<std::string, double> x = ticks(svg, "x"), y = ticks(svg, "y");
  ASSERT_TRUE(x.contains("0") && x.contains("20") && y.contains("0") && y.contains("20"));
  const double scale = (x.at("20") - x.at("0")) / 20;
  const Drawn aligned = decode(path_of(svg, "aligned-path"));
  ASSERT_FALSE(aligned.vertices.empty());
  EXPECT_NEAR(aligned.vertices[0].x, x.at("0") + 1 * scale, 0.011);
  EXPECT_NEAR(aligned.vertices[0].y, y.at("0") - 43 * scale, 0.011);

  if (std::system("test -x /usr/bin/python3") != 0) GTEST_SKIP() << "no /usr/bin/python3";
  const std::string parse =
      "/usr/bin/python3 -c 'import sys, xml.etree.ElementTree as E; "
      "E.parse(sys.argv[1])' " +
      dir_ + "/map.svg";
  EXPECT_EQ(std::system(parse.c_str()), 0) << "map.svg is not well-formed XML";
}

// Data lands where the axes say: a landmark at (x, y) m sits on the ticks labelled x and y, at
// one scale on both axes, y up; its 2-sigma ellipse has the covariance's axes and turn.
TEST_F(MapPicture, LandmarksLandOnTheirTicks) {
  write("landmarks.csv",
        "id,x,y,sxx,sxy,syy\n"
        "0,0,0,0.01,0,0.01\n"
        "1,100,0,0.01,0,0.01\n"
        "2,0,100,0.01,0,0.01\n"
        "3,100,100,0.01,0,0.01\n"
        "4,50,50,4,0,1\n"
        "5,20,80,2,1,2\n");
  const std::string svg = draw();
  const std::map<std::string, double> x = ticks(svg, "x"), y = ticks(svg, "y");
  ASSERT_TRUE(x.contains("0") && x.contains("100")) << svg.substr(0, 3000);
  ASSERT_TRUE(y.contains("0") && y.contains("100"));
  const double scale = (x.at("100") - x.at("0")) / 100;
  EXPECT_GT(scale, 0);
  EXPECT_NEAR(y.at("0") - y.at("100"), 100 * scale, 0.02);  // equal aspect, y up

  const Drawn dots = decode(path_of(svg, "landmarks"));
  ASSERT_EQ(dots.dots.size(), 6u);
  const Xy expected[] = {{0, 0}, {100, 0}, {0, 100}, {100, 100}, {50, 50}, {20, 80}};
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_NEAR(dots.dots[i].x, x.at("0") + expected[i].x * scale, 0.011) << i;
    EXPECT_NEAR(dots.dots[i].y, y.at("0") - expected[i].y * scale, 0.011) << i;
  }

  std::smatch m;
  const std::regex ellipse(
      "<ellipse cx=\"([-0-9.]+)\" cy=\"([-0-9.]+)\" rx=\"([-0-9.]+)\" "
      "ry=\"([-0-9.]+)\"( transform=\"rotate\\(([-0-9.]+) ([-0-9.]+) "
      "([-0-9.]+)\\)\")?/>");
  std::vector<std::smatch> ellipses;
  for (auto it = std::sregex_iterator(svg.begin(), svg.end(), ellipse);
       it != std::sregex_iterator(); ++it) {
    ellipses.push_back(*it);
  }
  ASSERT_EQ(ellipses.size(), 6u);
  // (50, 50), sxx 4, syy 1: semi-axes 2 sigma = 4 m along x and 2 m along y, not turned.
  const std::smatch& e = ellipses[4];
  EXPECT_NEAR(std::stod(e[1]), x.at("0") + 50 * scale, 0.011);
  EXPECT_NEAR(std::stod(e[2]), y.at("0") - 50 * scale, 0.011);
  EXPECT_NEAR(std::stod(e[3]), 4 * scale, 0.011);
  EXPECT_NEAR(std::stod(e[4]), 2 * scale, 0.011);
  EXPECT_FALSE(e[5].matched);
  // (20, 80), [[2, 1], [1, 2]]: eigenvalues 3 and 1, the major axis at +45 degrees, which is
  // -45 with the picture's y down.
  const std::smatch& f = ellipses[5];
  EXPECT_NEAR(std::stod(f[3]), 2 * std::sqrt(3.0) * scale, 0.011);
  EXPECT_NEAR(std::stod(f[4]), 2 * scale, 0.011);
  ASSERT_TRUE(f[5].matched);
  EXPECT_NEAR(std::stod(f[6]), -45, 0.05);
}

// The legend goes inside a small map's panel, where it covers least, unless it does not fit
// there (a narrow panel): then below it, as for a large map.
TEST_F(MapPicture, TheLegendGoesInsideTheMapOrBelowIt) {
  const auto rect_after = [](const std::string& svg, const std::string& marker) {
    std::smatch m;
    const std::size_t at = svg.find(marker);
    EXPECT_NE(at, std::string::npos) << marker;
    const std::string rest = svg.substr(at, 400);
    EXPECT_TRUE(std::regex_search(rest, m,
                                  std::regex("<rect x=\"([-0-9.]+)\" y=\"([-0-9.]+)\" "
                                             "width=\"([-0-9.]+)\" height=\"([-0-9.]+)\"")))
        << rest;
    return std::vector<double>{std::stod(m[1]), std::stod(m[2]), std::stod(m[3]), std::stod(m[4])};
  };
  write_path("truth.csv", 100, 40);
  write_landmarks("landmarks.csv", 20, true);
  std::string svg = draw();
  std::vector<double> panel = rect_after(svg, "<clipPath id=\"map-clip\">");
  std::vector<double> legend = rect_after(svg, "<g id=\"legend\"");
  EXPECT_GE(legend[0], panel[0]);
  EXPECT_GE(legend[1], panel[1]);
  EXPECT_LE(legend[0] + legend[2], panel[0] + panel[2]);
  EXPECT_LE(legend[1] + legend[3], panel[1] + panel[3]);

  // A path 1 m wide and 100 m tall: a panel a quarter as wide as it is tall.
  write("truth.csv", "t,x,y,theta\n0,0,0,0\n1,1,100,0\n");
  svg = draw();
  panel = rect_after(svg, "<clipPath id=\"map-clip\">");
  legend = rect_after(svg, "<g id=\"legend\"");
  EXPECT_NEAR(panel[2] * 4, panel[3], 0.02);
  EXPECT_GT(legend[1], panel[1] + panel[3]);
}

// A long run's paths are thinned to the bound, first and last poses kept; the file stays
// small whatever the length.
TEST_F(MapPicture, PathsOfAMillionPosesAreThinnedToTheBound) {
  write_path("truth.csv", 1'000'000, 1000);
  const std::string svg = draw();
  const Drawn truth = decode(path_of(svg, "true-path"));
  EXPECT_LE(truth.vertices.size(), kMaxPathPoints + 1);
  EXPECT_GE(truth.vertices.size(), kMaxPathPoints / 2);
  EXPECT_EQ(truth.subpaths, 1u);
  const std::map<std::string, double> x = ticks(svg, "x"), y = ticks(svg, "y");
  ASSERT_TRUE(x.contains("0") && x.contains("1000") && y.contains("0"));
  const double scale = (x.at("1000") - x.at("0")) / 1000;
  // The first pose, (1000, 0), and the last, one millionth of a turn before it.
  EXPECT_NEAR(truth.vertices.front().x, x.at("1000"), 0.011);
  EXPECT_NEAR(truth.vertices.front().y, y.at("0"), 0.011);
  EXPECT_NEAR(truth.vertices.back().y, y.at("0") + 2 * M_PI * 1000 / 1e6 * scale, 0.011);
  EXPECT_LT(svg.size(), std::size_t{1} << 20);
}

// Ellipses for a map of at most kMaxEllipseLandmarks; past that, dots alone.
TEST_F(MapPicture, EllipsesOnlyUpToTheLimit) {
  write_landmarks("landmarks.csv", kMaxEllipseLandmarks, true);
  std::string svg = draw();
  EXPECT_EQ(count(svg, "<ellipse"), kMaxEllipseLandmarks);
  EXPECT_EQ(decode(path_of(svg, "landmarks")).dots.size(), kMaxEllipseLandmarks);
  write_landmarks("landmarks.csv", kMaxEllipseLandmarks + 1, true);
  svg = draw();
  EXPECT_EQ(count(svg, "<ellipse"), 0u);
  EXPECT_EQ(decode(path_of(svg, "landmarks")).dots.size(), kMaxEllipseLandmarks + 1);
  EXPECT_NE(svg.find(">estimated map (best particle)<"), std::string::npos);
}

// A large map: dots thinned to the bound and said so, and a zoom panel on about
// kZoomWindowLandmarks true landmarks with each estimate joined to its truth (known
// association).
TEST_F(MapPicture, ALargeMapGetsThinnedDotsAndAZoomPanel) {
  write_landmarks("true_landmarks.csv", 60'000, false);
  write_landmarks("landmarks.csv", 60'000, true);
  write_path("truth.csv", 2000, 100);
  write_path("trajectory.csv", 2000, 100);
  write("metrics.json", R"({"association": "known"})");
  std::string svg = draw();
  const Drawn true_dots = decode(path_of(svg, "true-landmarks"));
  EXPECT_LE(true_dots.dots.size(), kMaxDots);
  EXPECT_EQ(true_dots.dots.size(), 15'000u);  // every 4th of 60000
  EXPECT_NE(svg.find(">true landmarks (1 in 4 shown)<"), std::string::npos);
  EXPECT_NE(svg.find(">estimated map (best particle) (1 in 4 shown)<"), std::string::npos);
  EXPECT_EQ(count(svg, "<ellipse"), decode(path_of(svg, "zoom-landmarks")).dots.size());
  const std::size_t in_window = decode(path_of(svg, "zoom-true-landmarks")).subpaths / 2;
  EXPECT_GT(in_window, 0.5 * kZoomWindowLandmarks);
  EXPECT_LT(in_window, 2 * kZoomWindowLandmarks);
  EXPECT_FALSE(path_of(svg, "zoom-true-path").empty());
  EXPECT_FALSE(path_of(svg, "zoom-estimated-path").empty());
  EXPECT_NE(svg.find("id=\"zoomed-window\""), std::string::npos);
  // Estimates on their true landmarks: zero-length links, one per estimate in the window.
  const Drawn links = decode(path_of(svg, "zoom-links"));
  EXPECT_EQ(links.subpaths, count(svg, "<ellipse"));

  write("metrics.json", R"({"association": "ml"})");
  svg = draw();
  EXPECT_TRUE(path_of(svg, "zoom-links").empty());
  EXPECT_NE(svg.find("id=\"zoom\""), std::string::npos);
}

// A malformed file is an error naming it and its line, and no picture is left.
TEST_F(MapPicture, AMalformedFileIsAnErrorNamingFileAndLine) {
  write_path("truth.csv", 10, 5);
  write("trajectory.csv", "t,x,y,theta\n0,1,2,0\n0,1,oops,0\n");
  std::string e = error();
  EXPECT_NE(e.find(dir_ + "/trajectory.csv:3: column 'y': 'oops' is not a number"),
            std::string::npos)
      << e;
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/map.svg"));
  write("trajectory.csv", "t,x,y\n0,1,2\n");
  e = error();
  EXPECT_NE(e.find(dir_ + "/trajectory.csv:1: header is 't,x,y'"), std::string::npos) << e;
  std::filesystem::remove(dir_ + "/trajectory.csv");
  write("metrics.json", "{\"seed\": 1,\n \"particles\": }");
  e = error();
  EXPECT_NE(e.find(dir_ + "/metrics.json: not valid JSON"), std::string::npos) << e;
  EXPECT_NE(e.find("line 2"), std::string::npos) << e;
  write("metrics.json", R"({"pose_alignment": {"rotation_deg": "x"}})");
  e = error();
  EXPECT_NE(e.find(dir_ + "/metrics.json: pose_alignment: expected numbers"), std::string::npos)
      << e;
  EXPECT_FALSE(std::filesystem::exists(dir_ + "/map.svg"));
}

// Every input may be absent: an empty directory gives empty axes and the plain title.
TEST_F(MapPicture, AbsentFilesAreFine) {
  std::string svg = draw();
  EXPECT_NE(svg.find(">fastslam run</text>"), std::string::npos);
  EXPECT_EQ(svg.find("<path id="), std::string::npos);
  EXPECT_NE(svg.find("</svg>\n"), std::string::npos);
  // Real data without truth: the estimate and GPS with its alignment.
  write_path("trajectory.csv", 100, 10);
  write("gps.csv", "t,x,y\n0,10,0\n");
  write("metrics.json", R"({"landmarks": 0, "gps_alignment": {"rotation_deg": 0, "x_m": 5,
                            "y_m": 0}, "gps_rmse_m": 3})");
  svg = draw();
  EXPECT_FALSE(path_of(svg, "aligned-path").empty());
  EXPECT_NE(svg.find(", 0 landmarks mapped:</text>"), std::string::npos);
  EXPECT_NE(svg.find(">GPS RMSE 3.00 m</text>"), std::string::npos);
}

}  // namespace
}  // namespace fastslam::tools
