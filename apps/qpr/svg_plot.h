// qpr — a small SVG chart writer (scatter, lines, histogram bars; linear or
// log axes; ticks, labels, legend). No plotting library is among the
// dependencies, and figures in docs/ must be regenerable by a command.
//
//     qpr::svg::Panel p;
//     p.title = "error vs bound";
//     p.x = {"true error", /*log=*/true};
//     p.y = {"bound", true};
//     p.series.push_back({"grid2d", "#1f77b4", qpr::svg::Mark::Points, xs, ys});
//     std::string svg = qpr::svg::render({p});
#pragma once

#include <cstddef>
#include <limits>
#include <string>
#include <vector>

namespace qpr::svg {

struct Axis {
  std::string label;
  bool log = false;
  // Data range; NaN means "from the data". Log axes use only positive values.
  double lo = std::numeric_limits<double>::quiet_NaN();
  double hi = std::numeric_limits<double>::quiet_NaN();
};

enum class Mark {
  Points,  // one circle per (x[i], y[i])
  Line,    // a polyline through (x[i], y[i])
  Bars,    // histogram: x holds y.size() + 1 bin edges, y the bar heights
};

struct Series {
  std::string label;  // legend entry; empty: not in the legend
  std::string color;  // any SVG colour, e.g. "#1f77b4"
  Mark mark = Mark::Points;
  std::vector<double> x, y;
  bool dashed = false;  // Line only
};

enum class Corner { TopLeft, TopRight, BottomLeft, BottomRight };

struct Panel {
  std::string title;
  Axis x, y;
  std::vector<Series> series;
  std::string note;                     // one line under the title (small, grey); may be empty
  Corner legend = Corner::TopLeft;      // where the legend box goes inside the plot area
};

// Renders the panels side by side into one standalone SVG document. Points
// that a log axis cannot show (≤ 0, NaN, ±inf) are skipped.
std::string render(const std::vector<Panel>& panels, int panel_width = 460, int panel_height = 360);

// A qualitative palette (Tableau 10) for series i.
const char* palette(std::size_t i);

}  // namespace qpr::svg
