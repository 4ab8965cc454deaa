// qpr viewer — a GLFW window with an OpenGL 3.3 core context, visible for
// the interactive viewer or hidden for headless rendering (which still needs
// an X server: run under `xvfb-run -a`, with Mesa's llvmpipe when there is no
// GPU).
#pragma once

#include "gl.h"

#include <string>

namespace qpr::viewer {

class GlContext {
 public:
  // Initialises GLFW, opens the window and makes its context current.
  // Throws std::runtime_error with GLFW's reason when there is no display or
  // no OpenGL 3.3 core context (the message says how to run headless).
  GlContext(int width, int height, const std::string& title, bool visible);
  ~GlContext();
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;

  GLFWwindow* window() const { return window_; }
  // GL_RENDERER and GL_VERSION, e.g. "llvmpipe (LLVM 15.0.6, 256 bits), 4.5 (Core Profile) Mesa 22.3.6".
  std::string description() const;

 private:
  GLFWwindow* window_ = nullptr;
};

}  // namespace qpr::viewer
