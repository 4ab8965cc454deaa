#include "context.h"

#include <stdexcept>

namespace qpr::viewer {

namespace {
std::string last_glfw_error() {
  const char* what = nullptr;
  glfwGetError(&what);
  return what ? what : "unknown GLFW error";
}
}  // namespace

GlContext::GlContext(int width, int height, const std::string& title, bool visible) {
  if (!glfwInit()) {
    throw std::runtime_error("cannot initialise GLFW (" + last_glfw_error() +
                             "); without a display run headless under `xvfb-run -a`");
  }
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  glfwWindowHint(GLFW_VISIBLE, visible ? GLFW_TRUE : GLFW_FALSE);
  window_ = glfwCreateWindow(width, height, title.c_str(), nullptr, nullptr);
  if (!window_) {
    const std::string why = last_glfw_error();
    glfwTerminate();
    throw std::runtime_error("cannot create an OpenGL 3.3 core context (" + why +
                             "); with Mesa try LIBGL_ALWAYS_SOFTWARE=1, headless run under `xvfb-run -a`");
  }
  glfwMakeContextCurrent(window_);
}

GlContext::~GlContext() {
  glfwDestroyWindow(window_);
  glfwTerminate();
}

std::string GlContext::description() const {
  const auto* renderer = reinterpret_cast<const char*>(glGetString(GL_RENDERER));
  const auto* version = reinterpret_cast<const char*>(glGetString(GL_VERSION));
  return std::string(renderer ? renderer : "?") + ", " + (version ? version : "?");
}

}  // namespace qpr::viewer
