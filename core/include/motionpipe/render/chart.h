// Plot panels on an Image: axes with ticks and labels, line series, bars, shaded spans, legends.
// Enough for the pipeline's summaries and reports, with the look of a plain matplotlib figure.
#pragma once

#include <string>
#include <vector>

#include "motionpipe/render/image.h"

namespace motionpipe::render {

class Panel {
 public:
  // The panel occupies [x, x + width) x [y, y + height) of `image`; the plot area leaves room for
  // the title, tick labels and axis labels.
  Panel(Image* image, int x, int y, int width, int height);

  void SetTitle(const std::string& title) { title_ = title; }
  void SetLabels(const std::string& x_label, const std::string& y_label) {
    x_label_ = x_label, y_label_ = y_label;
  }
  // Data ranges; log_x uses a base-10 logarithmic x axis (limits must be > 0).
  void SetLimits(double x_min, double x_max, double y_min, double y_max, bool log_x = false);
  // Categorical x tick labels at x = 0, 1, ... (bar charts).
  void SetCategories(const std::vector<std::string>& names) { categories_ = names; }

  // Draws the frame, grid, ticks and labels; call before the series.
  void DrawAxes();
  void LinePlot(const std::vector<double>& xs, const std::vector<double>& ys, Color c,
                double width = 2.0);
  void Bar(double x_left, double x_right, double height, Color c, double alpha = 1.0);
  void VerticalLine(double x, Color c, double width = 1.5, double dash = 6);
  void HorizontalLine(double y, Color c, double width = 1.5, double dash = 6);
  void ShadeX(double x0, double x1, Color c, double alpha = 0.2);
  void Legend(const std::vector<std::pair<std::string, Color>>& entries);
  // Free text inside the plot area, lines from the top-left.
  void Note(const std::vector<std::string>& lines, Color c = kBlack);

  double PixelX(double x) const;
  double PixelY(double y) const;

 private:
  Image* image_;
  int x_, y_, width_, height_;
  int left_, right_, top_, bottom_;  // plot area in image pixels
  double x_min_ = 0, x_max_ = 1, y_min_ = 0, y_max_ = 1;
  bool log_x_ = false;
  std::string title_, x_label_, y_label_;
  std::vector<std::string> categories_;
};

// "1.5", "20", "0.25", "1e+04": short tick labels.
std::string TickLabel(double value);
// Round tick positions covering [lo, hi] (about `count` of them).
std::vector<double> NiceTicks(double lo, double hi, int count = 5);

}  // namespace motionpipe::render
