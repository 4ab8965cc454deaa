#include "image.h"

#include <qpreduce/util/atomic_file.h>
#include <stb_image.h>
#include <stb_image_write.h>

#include <cstdlib>
#include <stdexcept>

namespace qpr::viewer {

void write_png(const std::string& path, const Image& image) {
  if (image.width <= 0 || image.height <= 0 || image.rgb.size() != 3u * image.width * image.height)
    throw std::invalid_argument(path + ": image has inconsistent size");
  std::string png;
  const auto append = [](void* context, void* data, int size) {
    static_cast<std::string*>(context)->append(static_cast<const char*>(data), static_cast<std::size_t>(size));
  };
  if (stbi_write_png_to_func(append, &png, image.width, image.height, 3, image.rgb.data(), 3 * image.width) == 0)
    throw std::runtime_error(path + ": cannot encode the PNG");
  qpreduce::write_file_atomically(path, png);
}

Image read_png(const std::string& path) {
  int w = 0, h = 0, channels = 0;
  unsigned char* data = stbi_load(path.c_str(), &w, &h, &channels, 3);
  if (!data) throw std::runtime_error(path + ": cannot read the image (" + stbi_failure_reason() + ")");
  Image image;
  image.width = w;
  image.height = h;
  image.rgb.assign(data, data + 3 * static_cast<size_t>(w) * h);
  stbi_image_free(data);
  return image;
}

namespace {
bool differs(const std::uint8_t* a, const std::uint8_t* b, int tolerance) {
  for (int c = 0; c < 3; ++c)
    if (std::abs(int(a[c]) - int(b[c])) > tolerance) return true;
  return false;
}
}  // namespace

double foreground_fraction(const Image& image, int tolerance) {
  if (image.width == 0 || image.height == 0) return 0.0;
  const std::uint8_t* bg = image.pixel(0, 0);
  size_t count = 0;
  for (int y = 0; y < image.height; ++y)
    for (int x = 0; x < image.width; ++x) count += differs(image.pixel(x, y), bg, tolerance);
  return static_cast<double>(count) / (static_cast<double>(image.width) * image.height);
}

double differing_fraction(const Image& a, const Image& b, int tolerance) {
  if (a.width != b.width || a.height != b.height)
    throw std::invalid_argument("differing_fraction: sizes differ");
  if (a.width == 0 || a.height == 0) return 0.0;
  size_t count = 0;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) count += differs(a.pixel(x, y), b.pixel(x, y), tolerance);
  return static_cast<double>(count) / (static_cast<double>(a.width) * a.height);
}

}  // namespace qpr::viewer
