#include "renderer.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace qpr::viewer {

using qpreduce::deform::Triangles;
using qpreduce::deform::Vertices;

const char* to_string(ColorMode mode) {
  switch (mode) {
    case ColorMode::Clusters: return "rotational clusters";
    case ColorMode::LinearProxies: return "linear proxies";
    case ColorMode::Patches: return "affine patches";
    case ColorMode::Deviation: return "deviation from rest";
  }
  return "?";
}

namespace {

// Texture units of the reconstruction passes.
enum Unit : int { kBasisUnit = 0, kCoordsUnit = 1, kPositionsUnit = 2, kRingOffsetsUnit = 3, kRingUnit = 4 };

const char* kReconstructVs = R"(#version 330 core
// p_v = centre + r0 · (B[3v .. 3v+2, :] · w), B stored as `texels` RGBA texels
// per row; r0 carries the normalisation's scale (Deformer::normalization).
uniform samplerBuffer basis;
uniform samplerBuffer coords;
uniform int texels;
uniform mat3 r0;
uniform vec3 centre;
out vec4 position;
void main() {
  int row = 3 * gl_VertexID * texels;
  vec3 p = vec3(0.0);
  for (int k = 0; k < texels; ++k) {
    vec4 w = texelFetch(coords, k);
    p.x += dot(texelFetch(basis, row + k), w);
    p.y += dot(texelFetch(basis, row + texels + k), w);
    p.z += dot(texelFetch(basis, row + 2 * texels + k), w);
  }
  position = vec4(centre + r0 * p, 1.0);
}
)";

const char* kNormalsVs = R"(#version 330 core
// Area-weighted vertex normal from the one-ring (CSR: offsets, corner pairs).
uniform samplerBuffer positions;
uniform isamplerBuffer ring_offsets;
uniform isamplerBuffer ring;
out vec3 normal;
void main() {
  int v = gl_VertexID;
  vec3 p = texelFetch(positions, v).xyz;
  int begin = texelFetch(ring_offsets, v).x, end = texelFetch(ring_offsets, v + 1).x;
  vec3 sum = vec3(0.0);
  for (int i = begin; i < end; ++i) {
    ivec2 bc = texelFetch(ring, i).xy;
    sum += cross(texelFetch(positions, bc.x).xyz - p, texelFetch(positions, bc.y).xyz - p);
  }
  float len = length(sum);
  normal = len > 0.0 ? sum / len : vec3(0.0);
}
)";

const char* kPassthroughFs = R"(#version 330 core
out vec4 frag;
void main() { frag = vec4(1.0); }
)";

const char* kShadeVs = R"(#version 330 core
layout(location = 0) in vec4 position;
layout(location = 1) in vec3 normal;
layout(location = 2) in vec3 color;
layout(location = 3) in vec3 rest;
uniform mat4 view;
uniform mat4 proj;
uniform int deviation;
uniform float deviation_scale;
out vec3 v_normal;
out vec3 v_color;
out vec3 v_pos;
vec3 ramp(float t) {  // blue → grey → red (diverging, "cool to warm")
  t = clamp(t, 0.0, 1.0);
  vec3 lo = vec3(0.23, 0.30, 0.75), mid = vec3(0.87, 0.87, 0.87), hi = vec3(0.71, 0.02, 0.15);
  return t < 0.5 ? mix(lo, mid, 2.0 * t) : mix(mid, hi, 2.0 * t - 1.0);
}
void main() {
  vec4 vp = view * vec4(position.xyz, 1.0);
  v_pos = vp.xyz;
  v_normal = mat3(view) * normal;
  v_color = deviation != 0 ? ramp(length(position.xyz - rest) / deviation_scale) : color;
  gl_Position = proj * vp;
}
)";

const char* kShadeFs = R"(#version 330 core
in vec3 v_normal;
in vec3 v_color;
in vec3 v_pos;
out vec4 frag;
void main() {
  vec3 v = normalize(-v_pos);
  float len = length(v_normal);
  vec3 n = len > 0.0 ? v_normal / len : v;
  if (dot(n, v) < 0.0) n = -n;  // two-sided
  vec3 key = normalize(vec3(0.35, 0.6, 1.0));
  float diffuse = 0.22 + 0.58 * max(dot(n, key), 0.0) + 0.22 * max(dot(n, v), 0.0);
  float specular = 0.18 * pow(max(dot(n, normalize(key + v)), 0.0), 48.0);
  frag = vec4(v_color * diffuse + vec3(specular), 1.0);
}
)";

const char* kMarkerVs = R"(#version 330 core
layout(location = 0) in vec4 position;
uniform mat4 view;
uniform mat4 proj;
uniform float size;
void main() {
  vec4 c = proj * view * vec4(position.xyz, 1.0);
  c.z -= 0.002 * c.w;  // drawn over the surface they sit on
  gl_Position = c;
  gl_PointSize = size;
}
)";

const char* kMarkerFs = R"(#version 330 core
uniform vec3 color;
out vec4 frag;
void main() {
  vec2 d = 2.0 * gl_PointCoord - 1.0;
  if (dot(d, d) > 1.0) discard;
  frag = vec4(color, 1.0);
}
)";

// Throws with the info log when `object` failed (shader compile or program link).
void check(GLuint object, bool program, const char* name) {
  GLint ok = 0;
  (program ? glGetProgramiv : glGetShaderiv)(object, program ? GL_LINK_STATUS : GL_COMPILE_STATUS, &ok);
  if (ok) return;
  char log[2048] = "";
  (program ? glGetProgramInfoLog : glGetShaderInfoLog)(object, sizeof log, nullptr, log);
  (program ? glDeleteProgram : glDeleteShader)(object);
  throw std::runtime_error(fmt::format("viewer: {} '{}' failed: {}", program ? "linking program" : "compiling shader", name, log));
}

GLuint compile(GLenum type, const char* source, const char* name) {
  const GLuint s = glCreateShader(type);
  glShaderSource(s, 1, &source, nullptr);
  glCompileShader(s);
  check(s, false, name);
  return s;
}

// Links vs + fs; `varying` (optional) is captured by transform feedback.
GLuint link(const char* vs, const char* fs, const char* name, const char* varying = nullptr) {
  const GLuint p = glCreateProgram();
  const GLuint v = compile(GL_VERTEX_SHADER, vs, name), f = compile(GL_FRAGMENT_SHADER, fs, name);
  glAttachShader(p, v);
  glAttachShader(p, f);
  if (varying) glTransformFeedbackVaryings(p, 1, &varying, GL_INTERLEAVED_ATTRIBS);
  glLinkProgram(p);
  glDeleteShader(v);
  glDeleteShader(f);
  check(p, true, name);
  return p;
}

GLint uniform(GLuint program, const char* name) { return glGetUniformLocation(program, name); }

GLuint make_buffer(GLenum target, GLsizeiptr bytes, const void* data, GLenum usage) {
  GLuint b = 0;
  glGenBuffers(1, &b);
  glBindBuffer(target, b);
  glBufferData(target, bytes, data, usage);
  return b;
}

GLuint make_buffer_texture(GLuint buffer, GLenum format) {
  GLuint t = 0;
  glGenTextures(1, &t);
  glBindTexture(GL_TEXTURE_BUFFER, t);
  glTexBuffer(GL_TEXTURE_BUFFER, format, buffer);
  glBindTexture(GL_TEXTURE_BUFFER, 0);
  return t;
}

void bind_buffer_texture(int unit, GLuint texture) {
  glActiveTexture(GL_TEXTURE0 + unit);
  glBindTexture(GL_TEXTURE_BUFFER, texture);
}

}  // namespace

// ---- RenderTarget ----

RenderTarget::~RenderTarget() { release(); }

void RenderTarget::release() {
  const GLuint fbos[] = {ms_fbo_, fbo_};
  const GLuint rbs[] = {ms_color_, ms_depth_, color_, depth_};
  if (ms_fbo_) glDeleteFramebuffers(2, fbos);
  if (ms_color_) glDeleteRenderbuffers(4, rbs);
  ms_fbo_ = ms_color_ = ms_depth_ = fbo_ = color_ = depth_ = 0;
}

void RenderTarget::resize(int width, int height, int samples) {
  if (width == width_ && height == height_ && ms_fbo_) return;
  if (width <= 0 || height <= 0) throw std::invalid_argument(fmt::format("render target: bad size {}×{}", width, height));
  release();
  GLint max_samples = 0;
  glGetIntegerv(GL_MAX_SAMPLES, &max_samples);
  samples = std::clamp(samples, 0, static_cast<int>(max_samples));
  GLuint rb[4];
  glGenRenderbuffers(4, rb);
  ms_color_ = rb[0], ms_depth_ = rb[1], color_ = rb[2], depth_ = rb[3];
  auto storage = [&](GLuint r, int s, GLenum format) {
    glBindRenderbuffer(GL_RENDERBUFFER, r);
    glRenderbufferStorageMultisample(GL_RENDERBUFFER, s, format, width, height);
  };
  storage(ms_color_, samples, GL_RGBA8);
  storage(ms_depth_, samples, GL_DEPTH_COMPONENT24);
  storage(color_, 0, GL_RGBA8);
  storage(depth_, 0, GL_DEPTH_COMPONENT24);
  GLuint fb[2];
  glGenFramebuffers(2, fb);
  ms_fbo_ = fb[0], fbo_ = fb[1];
  for (auto [f, c, d] : {std::tuple{ms_fbo_, ms_color_, ms_depth_}, std::tuple{fbo_, color_, depth_}}) {
    glBindFramebuffer(GL_FRAMEBUFFER, f);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_RENDERBUFFER, c);
    glFramebufferRenderbuffer(GL_FRAMEBUFFER, GL_DEPTH_ATTACHMENT, GL_RENDERBUFFER, d);
    const GLenum status = glCheckFramebufferStatus(GL_FRAMEBUFFER);
    if (status != GL_FRAMEBUFFER_COMPLETE)
      throw std::runtime_error(fmt::format("render target: framebuffer incomplete (0x{:x})", status));
  }
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
  width_ = width;
  height_ = height;
}

void RenderTarget::bind() const {
  glBindFramebuffer(GL_FRAMEBUFFER, ms_fbo_);
  glViewport(0, 0, width_, height_);
}

void RenderTarget::resolve() const {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, ms_fbo_);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, fbo_);
  glBlitFramebuffer(0, 0, width_, height_, 0, 0, width_, height_, GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT,
                    GL_NEAREST);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
}

namespace {
// glReadPixels of the bound read framebuffer, flipped so that row 0 is the top.
Image read_pixels(int width, int height) {
  Image image;
  image.width = width;
  image.height = height;
  image.rgb.resize(3 * static_cast<size_t>(width) * height);
  glPixelStorei(GL_PACK_ALIGNMENT, 1);
  std::vector<std::uint8_t> flipped(image.rgb.size());
  glReadPixels(0, 0, width, height, GL_RGB, GL_UNSIGNED_BYTE, flipped.data());
  const size_t row = 3 * static_cast<size_t>(width);
  for (int y = 0; y < height; ++y)
    std::copy_n(flipped.data() + (height - 1 - y) * row, row, image.rgb.data() + y * row);
  return image;
}
}  // namespace

Image RenderTarget::read_rgb() const {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
  Image image = read_pixels(width_, height_);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  return image;
}

Image read_window(int width, int height) {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  glReadBuffer(GL_BACK);
  return read_pixels(width, height);
}

float RenderTarget::read_depth(int x, int y) const {
  if (x < 0 || y < 0 || x >= width_ || y >= height_) return 1.0f;
  float depth = 1.0f;
  glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
  glReadPixels(x, height_ - 1 - y, 1, 1, GL_DEPTH_COMPONENT, GL_FLOAT, &depth);
  glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  return depth;
}

std::vector<float> RenderTarget::read_depth_buffer() const {
  std::vector<float> gl(static_cast<size_t>(width_) * height_), out(gl.size());
  glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
  glReadPixels(0, 0, width_, height_, GL_DEPTH_COMPONENT, GL_FLOAT, gl.data());
  glBindFramebuffer(GL_READ_FRAMEBUFFER, 0);
  for (int y = 0; y < height_; ++y)
    std::copy_n(gl.data() + static_cast<size_t>(height_ - 1 - y) * width_, width_, out.data() + static_cast<size_t>(y) * width_);
  return out;
}

void RenderTarget::blit_to_screen(int screen_width, int screen_height) const {
  glBindFramebuffer(GL_READ_FRAMEBUFFER, fbo_);
  glBindFramebuffer(GL_DRAW_FRAMEBUFFER, 0);
  glBlitFramebuffer(0, 0, width_, height_, 0, 0, screen_width, screen_height, GL_COLOR_BUFFER_BIT, GL_NEAREST);
  glBindFramebuffer(GL_FRAMEBUFFER, 0);
}

// ---- MeshRenderer ----

MeshRenderer::MeshRenderer(const Vertices& rest, const Triangles& faces) : n_(rest.rows()) {
  if (n_ == 0 || faces.rows() == 0) throw std::invalid_argument("viewer: the mesh has no vertex or no triangle to draw");
  if (faces.minCoeff() < 0 || faces.maxCoeff() >= n_)
    throw std::invalid_argument(fmt::format("viewer: a triangle index lies outside [0, {})", n_));
  reconstruct_prog_ = link(kReconstructVs, kPassthroughFs, "reconstruct", "position");
  normals_prog_ = link(kNormalsVs, kPassthroughFs, "normals", "normal");
  shade_prog_ = link(kShadeVs, kShadeFs, "shade");
  marker_prog_ = link(kMarkerVs, kMarkerFs, "marker");

  // One-ring table.
  const Eigen::Index k = faces.rows();
  ring_offsets_.assign(static_cast<size_t>(n_) + 1, 0);
  for (Eigen::Index f = 0; f < k; ++f)
    for (int c = 0; c < 3; ++c) ++ring_offsets_[faces(f, c) + 1];
  for (Eigen::Index v = 0; v < n_; ++v) ring_offsets_[v + 1] += ring_offsets_[v];
  ring_.resize(6 * static_cast<size_t>(k));
  std::vector<int> fill(ring_offsets_.begin(), ring_offsets_.end() - 1);
  for (Eigen::Index f = 0; f < k; ++f)
    for (int c = 0; c < 3; ++c) {
      const int v = faces(f, c), at = fill[v]++;
      ring_[2 * at] = faces(f, (c + 1) % 3);
      ring_[2 * at + 1] = faces(f, (c + 2) % 3);
    }

  positions_.assign(4 * static_cast<size_t>(n_), 1.0f);
  normals_.assign(3 * static_cast<size_t>(n_), 0.0f);
  std::vector<float> rest_f(3 * static_cast<size_t>(n_));
  for (Eigen::Index v = 0; v < n_; ++v)
    for (int a = 0; a < 3; ++a) rest_f[3 * v + a] = static_cast<float>(rest(v, a));
  std::vector<float> grey(3 * static_cast<size_t>(n_), 0.8f);
  std::vector<unsigned> indices(3 * static_cast<size_t>(k));
  for (Eigen::Index f = 0; f < k; ++f)
    for (int c = 0; c < 3; ++c) indices[3 * f + c] = static_cast<unsigned>(faces(f, c));
  index_count_ = static_cast<GLsizei>(indices.size());

  glGenVertexArrays(1, &vao_);
  glGenVertexArrays(1, &empty_vao_);
  glGenVertexArrays(1, &marker_vao_);
  glBindVertexArray(vao_);
  auto attribute = [](GLuint location, GLuint buffer, int size) {
    glBindBuffer(GL_ARRAY_BUFFER, buffer);
    glEnableVertexAttribArray(location);
    glVertexAttribPointer(location, size, GL_FLOAT, GL_FALSE, 0, nullptr);
  };
  position_buf_ = make_buffer(GL_ARRAY_BUFFER, positions_.size() * sizeof(float), nullptr, GL_DYNAMIC_COPY);
  normal_buf_ = make_buffer(GL_ARRAY_BUFFER, normals_.size() * sizeof(float), nullptr, GL_DYNAMIC_COPY);
  color_buf_ = make_buffer(GL_ARRAY_BUFFER, grey.size() * sizeof(float), grey.data(), GL_STATIC_DRAW);
  rest_buf_ = make_buffer(GL_ARRAY_BUFFER, rest_f.size() * sizeof(float), rest_f.data(), GL_STATIC_DRAW);
  attribute(0, position_buf_, 4);
  attribute(1, normal_buf_, 3);
  attribute(2, color_buf_, 3);
  attribute(3, rest_buf_, 3);
  index_buf_ = make_buffer(GL_ELEMENT_ARRAY_BUFFER, indices.size() * sizeof(unsigned), indices.data(), GL_STATIC_DRAW);
  glBindVertexArray(marker_vao_);
  attribute(0, position_buf_, 4);
  glGenBuffers(2, marker_buf_);
  glBindVertexArray(0);

  ring_offset_buf_ = make_buffer(GL_TEXTURE_BUFFER, ring_offsets_.size() * sizeof(int), ring_offsets_.data(), GL_STATIC_DRAW);
  ring_buf_ = make_buffer(GL_TEXTURE_BUFFER, ring_.size() * sizeof(int), ring_.data(), GL_STATIC_DRAW);
  ring_offset_tex_ = make_buffer_texture(ring_offset_buf_, GL_R32I);
  ring_tex_ = make_buffer_texture(ring_buf_, GL_RG32I);
  position_tex_ = make_buffer_texture(position_buf_, GL_RGBA32F);
  glBindBuffer(GL_TEXTURE_BUFFER, 0);

  // Rest pose on the CPU path until a frame arrives.
  upload_positions(rest);
}

MeshRenderer::~MeshRenderer() {
  const GLuint buffers[] = {position_buf_, normal_buf_, color_buf_, rest_buf_, index_buf_, marker_buf_[0], marker_buf_[1],
                            basis_buf_, w_buf_, ring_offset_buf_, ring_buf_};
  glDeleteBuffers(static_cast<GLsizei>(std::size(buffers)), buffers);
  const GLuint textures[] = {basis_tex_, w_tex_, position_tex_, ring_offset_tex_, ring_tex_};
  glDeleteTextures(static_cast<GLsizei>(std::size(textures)), textures);
  const GLuint vaos[] = {vao_, empty_vao_, marker_vao_};
  glDeleteVertexArrays(3, vaos);
  for (GLuint p : {reconstruct_prog_, normals_prog_, shade_prog_, marker_prog_}) glDeleteProgram(p);
}

bool MeshRenderer::upload_basis(const RowMatrixF& B, std::string* why) {
  if (B.rows() != 3 * n_)
    throw std::invalid_argument(fmt::format("upload_basis: expected {} rows (3n), got {}", 3 * n_, B.rows()));
  const Eigen::Index p = B.cols(), q = (p + 3) / 4;
  GLint max_texels = 0;
  glGetIntegerv(GL_MAX_TEXTURE_BUFFER_SIZE, &max_texels);
  const double texels = static_cast<double>(B.rows()) * q;
  if (p == 0 || texels > max_texels) {
    if (why)
      *why = fmt::format("the basis needs {:.0f} texels, GL_MAX_TEXTURE_BUFFER_SIZE is {}", texels, max_texels);
    basis_texels_ = 0;
    return false;
  }
  std::vector<float> padded(static_cast<size_t>(B.rows() * 4 * q), 0.0f);
  for (Eigen::Index r = 0; r < B.rows(); ++r) std::copy_n(B.row(r).data(), p, padded.data() + r * 4 * q);
  if (!basis_buf_) {
    glGenBuffers(1, &basis_buf_);
    glGenBuffers(1, &w_buf_);
  }
  glBindBuffer(GL_TEXTURE_BUFFER, basis_buf_);
  glBufferData(GL_TEXTURE_BUFFER, padded.size() * sizeof(float), padded.data(), GL_STATIC_DRAW);
  w_padded_.assign(static_cast<size_t>(4 * q), 0.0f);
  glBindBuffer(GL_TEXTURE_BUFFER, w_buf_);
  glBufferData(GL_TEXTURE_BUFFER, w_padded_.size() * sizeof(float), w_padded_.data(), GL_STREAM_DRAW);
  glBindBuffer(GL_TEXTURE_BUFFER, 0);
  if (!basis_tex_) {
    basis_tex_ = make_buffer_texture(basis_buf_, GL_RGBA32F);
    w_tex_ = make_buffer_texture(w_buf_, GL_RGBA32F);
  } else {  // re-attach: the buffers' storage changed
    glBindTexture(GL_TEXTURE_BUFFER, basis_tex_);
    glTexBuffer(GL_TEXTURE_BUFFER, GL_RGBA32F, basis_buf_);
    glBindTexture(GL_TEXTURE_BUFFER, w_tex_);
    glTexBuffer(GL_TEXTURE_BUFFER, GL_RGBA32F, w_buf_);
    glBindTexture(GL_TEXTURE_BUFFER, 0);
  }
  basis_texels_ = static_cast<GLint>(q);
  return true;
}

void MeshRenderer::reconstruct_gpu(const Eigen::VectorXf& w, const Eigen::Matrix3f& r0, const Eigen::Vector3f& centre) {
  if (!has_basis()) throw std::logic_error("reconstruct_gpu: no basis uploaded");
  if (w.size() > static_cast<Eigen::Index>(w_padded_.size()) || w.size() + 4 <= static_cast<Eigen::Index>(w_padded_.size()))
    throw std::invalid_argument(fmt::format("reconstruct_gpu: expected {} reduced coordinates, got {}",
                                            w_padded_.size(), w.size()));
  std::copy_n(w.data(), w.size(), w_padded_.data());
  glBindBuffer(GL_TEXTURE_BUFFER, w_buf_);
  glBufferSubData(GL_TEXTURE_BUFFER, 0, w_padded_.size() * sizeof(float), w_padded_.data());
  glBindBuffer(GL_TEXTURE_BUFFER, 0);

  glEnable(GL_RASTERIZER_DISCARD);
  glBindVertexArray(empty_vao_);
  // Pass 1: positions.
  glUseProgram(reconstruct_prog_);
  bind_buffer_texture(kBasisUnit, basis_tex_);
  bind_buffer_texture(kCoordsUnit, w_tex_);
  glUniform1i(uniform(reconstruct_prog_, "basis"), kBasisUnit);
  glUniform1i(uniform(reconstruct_prog_, "coords"), kCoordsUnit);
  glUniform1i(uniform(reconstruct_prog_, "texels"), basis_texels_);
  glUniformMatrix3fv(uniform(reconstruct_prog_, "r0"), 1, GL_FALSE, r0.data());
  glUniform3fv(uniform(reconstruct_prog_, "centre"), 1, centre.data());
  glBindBufferBase(GL_TRANSFORM_FEEDBACK_BUFFER, 0, position_buf_);
  glBeginTransformFeedback(GL_POINTS);
  glDrawArrays(GL_POINTS, 0, static_cast<GLsizei>(n_));
  glEndTransformFeedback();
  // Pass 2: normals from the new positions.
  glUseProgram(normals_prog_);
  bind_buffer_texture(kPositionsUnit, position_tex_);
  bind_buffer_texture(kRingOffsetsUnit, ring_offset_tex_);
  bind_buffer_texture(kRingUnit, ring_tex_);
  glUniform1i(uniform(normals_prog_, "positions"), kPositionsUnit);
  glUniform1i(uniform(normals_prog_, "ring_offsets"), kRingOffsetsUnit);
  glUniform1i(uniform(normals_prog_, "ring"), kRingUnit);
  glBindBufferBase(GL_TRANSFORM_FEEDBACK_BUFFER, 0, normal_buf_);
  glBeginTransformFeedback(GL_POINTS);
  glDrawArrays(GL_POINTS, 0, static_cast<GLsizei>(n_));
  glEndTransformFeedback();
  glBindBufferBase(GL_TRANSFORM_FEEDBACK_BUFFER, 0, 0);
  bind_buffer_texture(kPositionsUnit, 0);
  glActiveTexture(GL_TEXTURE0);
  glDisable(GL_RASTERIZER_DISCARD);
  glBindVertexArray(0);
  glUseProgram(0);
}

void MeshRenderer::compute_normals_cpu() {
  for (Eigen::Index v = 0; v < n_; ++v) {
    const Eigen::Map<const Eigen::Vector3f> p(positions_.data() + 4 * v);
    Eigen::Vector3f sum = Eigen::Vector3f::Zero();
    for (int i = ring_offsets_[v]; i < ring_offsets_[v + 1]; ++i) {
      const Eigen::Map<const Eigen::Vector3f> b(positions_.data() + 4 * ring_[2 * i]);
      const Eigen::Map<const Eigen::Vector3f> c(positions_.data() + 4 * ring_[2 * i + 1]);
      sum += (b - p).cross(c - p);
    }
    const float len = sum.norm();
    Eigen::Map<Eigen::Vector3f>(normals_.data() + 3 * v) = len > 0.0f ? Eigen::Vector3f(sum / len) : Eigen::Vector3f::Zero();
  }
}

void MeshRenderer::upload_positions(const Vertices& V) {
  if (V.rows() != n_) throw std::invalid_argument(fmt::format("upload_positions: expected {} vertices, got {}", n_, V.rows()));
  for (Eigen::Index v = 0; v < n_; ++v)
    for (int a = 0; a < 3; ++a) positions_[4 * v + a] = static_cast<float>(V(v, a));
  compute_normals_cpu();
  glBindBuffer(GL_ARRAY_BUFFER, position_buf_);
  glBufferSubData(GL_ARRAY_BUFFER, 0, positions_.size() * sizeof(float), positions_.data());
  glBindBuffer(GL_ARRAY_BUFFER, normal_buf_);
  glBufferSubData(GL_ARRAY_BUFFER, 0, normals_.size() * sizeof(float), normals_.data());
  glBindBuffer(GL_ARRAY_BUFFER, 0);
}

void MeshRenderer::read_positions(Vertices* V) const {
  std::vector<float> buffer(4 * static_cast<size_t>(n_));
  glBindBuffer(GL_ARRAY_BUFFER, position_buf_);
  glGetBufferSubData(GL_ARRAY_BUFFER, 0, buffer.size() * sizeof(float), buffer.data());
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  V->resize(n_, 3);
  for (Eigen::Index v = 0; v < n_; ++v)
    for (int a = 0; a < 3; ++a) (*V)(v, a) = buffer[4 * v + a];
}

void MeshRenderer::set_colors(const std::vector<Eigen::Vector3f>& colors) {
  if (static_cast<Eigen::Index>(colors.size()) != n_)
    throw std::invalid_argument(fmt::format("set_colors: expected {} colours, got {}", n_, colors.size()));
  glBindBuffer(GL_ARRAY_BUFFER, color_buf_);
  glBufferSubData(GL_ARRAY_BUFFER, 0, colors.size() * sizeof(Eigen::Vector3f), colors.data());
  glBindBuffer(GL_ARRAY_BUFFER, 0);
}

void MeshRenderer::set_markers(int slot, const std::vector<unsigned>& vertices) {
  if (slot < 0 || slot > 1) throw std::invalid_argument("set_markers: slot must be 0 or 1");
  for (unsigned v : vertices)
    if (v >= n_) throw std::invalid_argument(fmt::format("set_markers: vertex {} outside [0, {})", v, n_));
  glBindBuffer(GL_ARRAY_BUFFER, marker_buf_[slot]);  // an index buffer, filled outside any VAO
  glBufferData(GL_ARRAY_BUFFER, vertices.size() * sizeof(unsigned), vertices.data(), GL_DYNAMIC_DRAW);
  glBindBuffer(GL_ARRAY_BUFFER, 0);
  marker_count_[slot] = static_cast<GLsizei>(vertices.size());
}

void MeshRenderer::draw(const Camera& camera, int width, int height, const Style& style) const {
  glClearColor(style.background.x(), style.background.y(), style.background.z(), 1.0f);
  glClear(GL_COLOR_BUFFER_BIT | GL_DEPTH_BUFFER_BIT);
  glEnable(GL_DEPTH_TEST);
  glDisable(GL_CULL_FACE);
  const Eigen::Matrix4f view = camera.view();
  const Eigen::Matrix4f proj = camera.projection(static_cast<float>(width) / std::max(height, 1));
  glUseProgram(shade_prog_);
  glUniformMatrix4fv(uniform(shade_prog_, "view"), 1, GL_FALSE, view.data());
  glUniformMatrix4fv(uniform(shade_prog_, "proj"), 1, GL_FALSE, proj.data());
  glUniform1i(uniform(shade_prog_, "deviation"), style.mode == ColorMode::Deviation);
  glUniform1f(uniform(shade_prog_, "deviation_scale"), std::max(style.deviation_scale, 1e-12f));
  glBindVertexArray(vao_);
  glDrawElements(GL_TRIANGLES, index_count_, GL_UNSIGNED_INT, nullptr);

  glEnable(GL_PROGRAM_POINT_SIZE);
  glUseProgram(marker_prog_);
  glUniformMatrix4fv(uniform(marker_prog_, "view"), 1, GL_FALSE, view.data());
  glUniformMatrix4fv(uniform(marker_prog_, "proj"), 1, GL_FALSE, proj.data());
  glUniform1f(uniform(marker_prog_, "size"), style.marker_size);
  glBindVertexArray(marker_vao_);
  const Eigen::Vector3f colors[2] = {{0.95f, 0.55f, 0.05f}, {0.1f, 0.75f, 0.95f}};
  for (int slot = 0; slot < 2; ++slot) {
    if (marker_count_[slot] == 0) continue;
    glUniform3fv(uniform(marker_prog_, "color"), 1, colors[slot].data());
    glBindBuffer(GL_ELEMENT_ARRAY_BUFFER, marker_buf_[slot]);
    glDrawElements(GL_POINTS, marker_count_[slot], GL_UNSIGNED_INT, nullptr);
  }
  glBindVertexArray(0);
  glUseProgram(0);
}

}  // namespace qpr::viewer
