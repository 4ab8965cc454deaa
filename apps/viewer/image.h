// qpr viewer — 8-bit RGB images: PNG read/write (stb_image, Debian libstb)
// and the two measurements the headless test needs.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace qpr::viewer {

// width × height RGB pixels, row 0 at the top, 3 bytes per pixel.
struct Image {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;  // 3·width·height

  const std::uint8_t* pixel(int x, int y) const { return rgb.data() + 3 * (static_cast<size_t>(y) * width + x); }
};

// Throws std::runtime_error naming the file when it cannot be written/read.
void write_png(const std::string& path, const Image& image);
Image read_png(const std::string& path);

// Fraction of pixels that differ from the top-left pixel (the background) by
// more than `tolerance` in some channel: 0 for a blank image.
double foreground_fraction(const Image& image, int tolerance = 8);
// Fraction of pixels where a and b differ by more than `tolerance` in some
// channel. Throws std::invalid_argument when the sizes differ.
double differing_fraction(const Image& a, const Image& b, int tolerance = 8);

}  // namespace qpr::viewer
