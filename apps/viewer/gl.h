// qpr viewer — the OpenGL 3.3 core declarations. Linux's libGL (glvnd)
// exports every core entry point, so the prototypes are declared directly
// (GL_GLEXT_PROTOTYPES) instead of going through a loader; GLFW is told not
// to include its own GL header.
#pragma once

#ifndef GL_GLEXT_PROTOTYPES
#define GL_GLEXT_PROTOTYPES 1
#endif
#include <GL/gl.h>
#include <GL/glext.h>

#ifndef GLFW_INCLUDE_NONE
#define GLFW_INCLUDE_NONE
#endif
#include <GLFW/glfw3.h>
