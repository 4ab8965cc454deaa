#include "svg_plot.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <sstream>

namespace qpr::svg {

namespace {

// Plot-area margins inside a panel, in pixels.
constexpr double kLeft = 72, kRight = 18, kTop = 52, kBottom = 56;
constexpr int kMaxMajorTicks = 8;

std::string escape(const std::string& text) {
  std::string out;
  out.reserve(text.size());
  for (char c : text) {
    switch (c) {
      case '&': out += "&amp;"; break;
      case '<': out += "&lt;"; break;
      case '>': out += "&gt;"; break;
      case '"': out += "&quot;"; break;
      default: out += c;
    }
  }
  return out;
}

std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2f", v);
  return buf;
}

std::string tick_text(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

bool usable(double v, bool log) { return std::isfinite(v) && (!log || v > 0.0); }

// A linear tick step of 1, 2 or 5 × 10^k giving at most kMaxMajorTicks ticks.
double nice_step(double range) {
  if (!(range > 0.0)) return 1.0;
  const double raw = range / kMaxMajorTicks;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0})
    if (m * p >= raw) return m * p;
  return 10.0 * p;
}

struct Scale {
  bool log = false;
  double lo = 0.0, hi = 1.0;      // data range (in data units)
  double p0 = 0.0, p1 = 1.0;      // pixel range
  double t(double v) const { return log ? std::log10(v) : v; }
  double operator()(double v) const { return p0 + (t(v) - t(lo)) / (t(hi) - t(lo)) * (p1 - p0); }
};

// Fills lo/hi from the data when the axis leaves them open.
void resolve_range(const Axis& axis, const std::vector<double>& values, bool zero_based, Scale* s) {
  double lo = axis.lo, hi = axis.hi;
  double dmin = std::numeric_limits<double>::infinity(), dmax = -dmin;
  for (double v : values)
    if (usable(v, axis.log)) dmin = std::min(dmin, v), dmax = std::max(dmax, v);
  if (!std::isfinite(dmin)) dmin = axis.log ? 0.1 : 0.0, dmax = axis.log ? 10.0 : 1.0;
  if (axis.log) {
    if (std::isnan(lo)) lo = std::pow(10.0, std::floor(std::log10(dmin)));
    if (std::isnan(hi)) hi = std::pow(10.0, std::ceil(std::log10(dmax)));
    if (!(hi > lo)) hi = lo * 10.0;
  } else {
    if (zero_based) dmin = std::min(dmin, 0.0);
    if (!(dmax > dmin)) dmax = dmin + 1.0;
    const double step = nice_step(dmax - dmin);
    if (std::isnan(lo)) lo = std::floor(dmin / step) * step;
    if (std::isnan(hi)) hi = std::ceil(dmax / step) * step;
    if (!(hi > lo)) hi = lo + 1.0;
  }
  s->log = axis.log;
  s->lo = lo;
  s->hi = hi;
}

struct Tick {
  double value;
  bool major;
};

std::vector<Tick> ticks(const Scale& s) {
  std::vector<Tick> out;
  if (s.log) {
    const int k0 = static_cast<int>(std::ceil(std::log10(s.lo) - 1e-9));
    const int k1 = static_cast<int>(std::floor(std::log10(s.hi) + 1e-9));
    const int decades = std::max(1, k1 - k0);
    const int every = (decades + kMaxMajorTicks - 1) / kMaxMajorTicks;
    for (int k = k0 - 1; k <= k1; ++k) {
      const double base = std::pow(10.0, k);
      if (k >= k0 && (k - k0) % every == 0) out.push_back({base, true});
      if (every == 1)
        for (int m = 2; m <= 9; ++m) {
          const double v = m * base;
          if (v > s.lo * (1 + 1e-12) && v < s.hi * (1 - 1e-12)) out.push_back({v, false});
        }
    }
  } else {
    const double step = nice_step(s.hi - s.lo);
    for (double v = std::ceil(s.lo / step - 1e-9) * step; v <= s.hi + 1e-9 * step; v += step)
      out.push_back({std::abs(v) < 1e-12 * step ? 0.0 : v, true});
  }
  return out;
}

void tick_label(std::ostringstream& os, const Scale& s, double v, double x, double y, const char* anchor) {
  os << "<text x=\"" << num(x) << "\" y=\"" << num(y) << "\" text-anchor=\"" << anchor << "\">";
  if (s.log) {
    const long k = std::lround(std::log10(v));
    os << "10<tspan dy=\"-6\" font-size=\"9\">" << k << "</tspan>";
  } else {
    os << escape(tick_text(v));
  }
  os << "</text>\n";
}

// The plot area of a panel, in SVG pixels.
struct Box {
  double x0, x1, y0, y1;
};

// The panel's two axes, from its ranges and data, mapped onto the box.
void panel_scales(const Panel& panel, const Box& box, Scale* sx, Scale* sy) {
  std::vector<double> xs, ys;
  bool bars = false;
  for (const Series& s : panel.series) {
    xs.insert(xs.end(), s.x.begin(), s.x.end());
    ys.insert(ys.end(), s.y.begin(), s.y.end());
    bars = bars || s.mark == Mark::Bars;
  }
  resolve_range(panel.x, xs, false, sx);
  resolve_range(panel.y, ys, bars, sy);
  sx->p0 = box.x0, sx->p1 = box.x1;
  sy->p0 = box.y1, sy->p1 = box.y0;  // SVG y grows downwards
}

// Grid lines, ticks and tick labels of both axes.
void render_grid(std::ostringstream& os, const Scale& sx, const Scale& sy, const Box& b) {
  os << "<g font-size=\"11\" fill=\"#333\">\n";
  for (const Tick& t : ticks(sx)) {
    const double px = sx(t.value);
    if (t.major)
      os << "<line x1=\"" << num(px) << "\" y1=\"" << num(b.y0) << "\" x2=\"" << num(px) << "\" y2=\"" << num(b.y1)
         << "\" stroke=\"#e6e6e6\"/>\n";
    os << "<line x1=\"" << num(px) << "\" y1=\"" << num(b.y1) << "\" x2=\"" << num(px) << "\" y2=\""
       << num(b.y1 + (t.major ? 5 : 3)) << "\" stroke=\"#333\"/>\n";
    if (t.major) tick_label(os, sx, t.value, px, b.y1 + 18, "middle");
  }
  for (const Tick& t : ticks(sy)) {
    const double py = sy(t.value);
    if (t.major)
      os << "<line x1=\"" << num(b.x0) << "\" y1=\"" << num(py) << "\" x2=\"" << num(b.x1) << "\" y2=\"" << num(py)
         << "\" stroke=\"#e6e6e6\"/>\n";
    os << "<line x1=\"" << num(b.x0 - (t.major ? 5 : 3)) << "\" y1=\"" << num(py) << "\" x2=\"" << num(b.x0)
       << "\" y2=\"" << num(py) << "\" stroke=\"#333\"/>\n";
    if (t.major) tick_label(os, sy, t.value, b.x0 - 8, py + 4, "end");
  }
  os << "</g>\n";
}

// The frame, the axis labels, the title and the note.
void render_frame(std::ostringstream& os, const Panel& panel, const Box& b, double ox, double height) {
  os << "<rect x=\"" << num(b.x0) << "\" y=\"" << num(b.y0) << "\" width=\"" << num(b.x1 - b.x0) << "\" height=\""
     << num(b.y1 - b.y0) << "\" fill=\"none\" stroke=\"#333\"/>\n";
  os << "<text x=\"" << num((b.x0 + b.x1) / 2) << "\" y=\"" << num(height - 14)
     << "\" text-anchor=\"middle\" font-size=\"13\">" << escape(panel.x.label) << "</text>\n";
  os << "<text transform=\"translate(" << num(ox + 18) << "," << num((b.y0 + b.y1) / 2)
     << ") rotate(-90)\" text-anchor=\"middle\" font-size=\"13\">" << escape(panel.y.label) << "</text>\n";
  os << "<text x=\"" << num((b.x0 + b.x1) / 2) << "\" y=\"20\" text-anchor=\"middle\" font-size=\"15\" "
        "font-weight=\"bold\">"
     << escape(panel.title) << "</text>\n";
  if (!panel.note.empty())
    os << "<text x=\"" << num((b.x0 + b.x1) / 2) << "\" y=\"38\" text-anchor=\"middle\" font-size=\"11\" "
          "fill=\"#666\">"
       << escape(panel.note) << "</text>\n";
}

// One series as points, a polyline or bars (x holds the bar edges).
void render_series(std::ostringstream& os, const Series& s, const Scale& sx, const Scale& sy) {
  if (s.mark == Mark::Points) {
    os << "<g fill=\"" << s.color << "\" fill-opacity=\"0.65\" stroke=\"none\">\n";
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!usable(s.x[i], sx.log) || !usable(s.y[i], sy.log)) continue;
      os << "<circle cx=\"" << num(sx(s.x[i])) << "\" cy=\"" << num(sy(s.y[i])) << "\" r=\"2.6\"/>\n";
    }
    os << "</g>\n";
  } else if (s.mark == Mark::Line) {
    os << "<polyline fill=\"none\" stroke=\"" << s.color << "\" stroke-width=\"1.5\""
       << (s.dashed ? " stroke-dasharray=\"6,4\"" : "") << " points=\"";
    for (size_t i = 0; i < s.x.size() && i < s.y.size(); ++i) {
      if (!usable(s.x[i], sx.log) || !usable(s.y[i], sy.log)) continue;
      os << num(sx(s.x[i])) << "," << num(sy(s.y[i])) << " ";
    }
    os << "\"/>\n";
  } else {  // Bars
    os << "<g fill=\"" << s.color << "\" fill-opacity=\"0.8\" stroke=\"#fff\" stroke-width=\"0.5\">\n";
    for (size_t i = 0; i < s.y.size() && i + 1 < s.x.size(); ++i) {
      if (!(s.y[i] > 0.0) || !usable(s.x[i], sx.log) || !usable(s.x[i + 1], sx.log)) continue;
      const double left = sx(s.x[i]), right = sx(s.x[i + 1]), top = sy(s.y[i]), base = sy(std::max(sy.lo, 0.0));
      os << "<rect x=\"" << num(left) << "\" y=\"" << num(top) << "\" width=\"" << num(right - left)
         << "\" height=\"" << num(base - top) << "\"/>\n";
    }
    os << "</g>\n";
  }
}

// The legend box in the panel's corner: one row per labelled series.
void render_legend(std::ostringstream& os, const Panel& panel, const Box& b) {
  std::vector<const Series*> entries;
  size_t longest = 0;
  for (const Series& s : panel.series)
    if (!s.label.empty()) entries.push_back(&s), longest = std::max(longest, s.label.size());
  if (entries.empty()) return;
  const double row = 16, box_w = 34 + 6.5 * static_cast<double>(longest), box_h = row * entries.size() + 8;
  const bool left = panel.legend == Corner::TopLeft || panel.legend == Corner::BottomLeft;
  const bool top = panel.legend == Corner::TopLeft || panel.legend == Corner::TopRight;
  const double bx = left ? b.x0 + 8 : b.x1 - 8 - box_w, by = top ? b.y0 + 8 : b.y1 - 8 - box_h;
  os << "<g font-size=\"11\">\n<rect x=\"" << num(bx) << "\" y=\"" << num(by) << "\" width=\"" << num(box_w)
     << "\" height=\"" << num(box_h) << "\" fill=\"#fff\" fill-opacity=\"0.9\" stroke=\"#bbb\"/>\n";
  for (size_t i = 0; i < entries.size(); ++i) {
    const Series& s = *entries[i];
    const double cy = by + 4 + row * (static_cast<double>(i) + 0.5);
    const double mx = bx + 14;
    if (s.mark == Mark::Points)
      os << "<circle cx=\"" << num(mx) << "\" cy=\"" << num(cy) << "\" r=\"3.5\" fill=\"" << s.color << "\"/>\n";
    else if (s.mark == Mark::Line)
      os << "<line x1=\"" << num(mx - 9) << "\" y1=\"" << num(cy) << "\" x2=\"" << num(mx + 9) << "\" y2=\""
         << num(cy) << "\" stroke=\"" << s.color << "\" stroke-width=\"1.5\""
         << (s.dashed ? " stroke-dasharray=\"4,3\"" : "") << "/>\n";
    else
      os << "<rect x=\"" << num(mx - 6) << "\" y=\"" << num(cy - 5) << "\" width=\"12\" height=\"10\" fill=\""
         << s.color << "\"/>\n";
    os << "<text x=\"" << num(mx + 14) << "\" y=\"" << num(cy + 4) << "\">" << escape(s.label) << "</text>\n";
  }
  os << "</g>\n";
}

void render_panel(std::ostringstream& os, const Panel& panel, int index, double ox, double width, double height) {
  const Box box{ox + kLeft, ox + width - kRight, kTop, height - kBottom};
  Scale sx, sy;
  panel_scales(panel, box, &sx, &sy);
  const std::string clip = "plot-area-" + std::to_string(index);
  os << "<clipPath id=\"" << clip << "\"><rect x=\"" << num(box.x0) << "\" y=\"" << num(box.y0) << "\" width=\""
     << num(box.x1 - box.x0) << "\" height=\"" << num(box.y1 - box.y0) << "\"/></clipPath>\n";
  render_grid(os, sx, sy, box);
  render_frame(os, panel, box, ox, height);
  // Series, clipped to the plot area.
  os << "<g clip-path=\"url(#" << clip << ")\">\n";
  for (const Series& s : panel.series) render_series(os, s, sx, sy);
  os << "</g>\n";
  render_legend(os, panel, box);
}

}  // namespace

const char* palette(std::size_t i) {
  static const char* colors[] = {"#4e79a7", "#f28e2b", "#e15759", "#76b7b2", "#59a14f",
                                 "#edc948", "#b07aa1", "#ff9da7", "#9c755f", "#bab0ac"};
  return colors[i % (sizeof colors / sizeof *colors)];
}

std::string render(const std::vector<Panel>& panels, int panel_width, int panel_height) {
  const double w = panel_width, h = panel_height;
  const double total = w * static_cast<double>(std::max<size_t>(1, panels.size()));
  std::ostringstream os;
  os << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
     << "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"" << num(total) << "\" height=\"" << num(h)
     << "\" viewBox=\"0 0 " << num(total) << " " << num(h) << "\" font-family=\"Helvetica, Arial, sans-serif\">\n"
     << "<rect width=\"100%\" height=\"100%\" fill=\"#fff\"/>\n";
  for (size_t i = 0; i < panels.size(); ++i)
    render_panel(os, panels[i], static_cast<int>(i), w * static_cast<double>(i), w, h);
  os << "</svg>\n";
  return os.str();
}

}  // namespace qpr::svg
