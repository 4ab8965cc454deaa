// qpr viewer — drawing a deforming mesh with OpenGL 3.3 core, and the GPU
// side of the reconstruction (paper Fig. 5 step 5).
//
// Positions live in one GPU buffer (n × vec4) that two paths can fill:
//   * GPU: the reconstruction basis B (3n × p float, row 3v + a = coordinate
//     a of vertex v, see Deformer::reconstruction_basis) is uploaded ONCE into
//     a texture buffer (RGBA32F, each row padded to q = ⌈p/4⌉ texels); per
//     frame only w = [X; S_local] (p floats) and r₀ (3 × 3) are sent, and a
//     vertex shader computes p_v = r₀·(B_{3v..3v+2,:}·w) for every vertex,
//     captured by transform feedback (rasterizer off, one point per vertex).
//     A second transform-feedback pass computes area-weighted vertex normals
//     n_v = normalize(Σ_{(v,b,c) ∋ v} (p_b − p_v) × (p_c − p_v)) from the
//     one-ring (a CSR table in integer texture buffers).
//   * CPU: positions computed by the Deformer are uploaded, with the same
//     normals computed on the CPU.
// The same buffers then feed the shading pass, so the two paths draw the
// same way and read_positions() can compare them.
#pragma once

#include "camera.h"
#include "gl.h"
#include "image.h"

#include <qpreduce/deform/mesh/mesh.h>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <string>
#include <vector>

namespace qpr::viewer {

using RowMatrixF = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// A framebuffer to draw the scene into: multisampled colour + depth, resolved
// into a single-sample one that screenshots and picking read.
class RenderTarget {
 public:
  RenderTarget() = default;
  ~RenderTarget();
  RenderTarget(const RenderTarget&) = delete;
  RenderTarget& operator=(const RenderTarget&) = delete;

  // (Re)allocates for width × height pixels with `samples` MSAA samples
  // (clamped to GL_MAX_SAMPLES). Throws std::runtime_error when incomplete.
  void resize(int width, int height, int samples);
  void bind() const;     // draw into the multisampled buffer
  void resolve() const;  // multisampled → single-sample (colour and depth)
  // After resolve(): the image (row 0 at the top) and the window-space depth
  // in [0, 1] at pixel (x, y) from the top-left.
  Image read_rgb() const;
  float read_depth(int x, int y) const;
  // After resolve(): all depths, width × height, row 0 at the top.
  std::vector<float> read_depth_buffer() const;
  // After resolve(): copies the colour to the default framebuffer.
  void blit_to_screen(int screen_width, int screen_height) const;
  int width() const { return width_; }
  int height() const { return height_; }

 private:
  void release();
  GLuint ms_fbo_ = 0, ms_color_ = 0, ms_depth_ = 0;
  GLuint fbo_ = 0, color_ = 0, depth_ = 0;
  int width_ = 0, height_ = 0;
};

// The default framebuffer's back buffer (width × height, row 0 at the top):
// the window as it will be shown, panels included.
Image read_window(int width, int height);

enum class ColorMode { Clusters, LinearProxies, Patches, Deviation };
const char* to_string(ColorMode mode);

class MeshRenderer {
 public:
  // `rest`: n × 3 rest positions; `faces`: k × 3 triangles drawn (for tets
  // the boundary), indices in [0, n). Needs a current GL 3.3 core context;
  // throws std::runtime_error when a shader does not compile.
  MeshRenderer(const qpreduce::deform::Vertices& rest, const qpreduce::deform::Triangles& faces);
  ~MeshRenderer();
  MeshRenderer(const MeshRenderer&) = delete;
  MeshRenderer& operator=(const MeshRenderer&) = delete;

  // ---- GPU reconstruction ----
  // Uploads B (3n × p). Returns false, with the reason in *why, when the GPU
  // cannot hold it (more texels than GL_MAX_TEXTURE_BUFFER_SIZE); the caller
  // then uses the CPU path. Throws std::invalid_argument when B has not 3n rows.
  bool upload_basis(const RowMatrixF& B, std::string* why);
  bool has_basis() const { return basis_texels_ > 0; }
  // Positions c + M·(B_v·w) and normals from w (p entries), M (σ·r₀) and c
  // (Deformer::normalization), computed on the GPU.
  void reconstruct_gpu(const Eigen::VectorXf& w, const Eigen::Matrix3f& M, const Eigen::Vector3f& centre);

  // ---- CPU path ----
  // Uploads V (n × 3) and normals computed on the CPU.
  void upload_positions(const qpreduce::deform::Vertices& V);

  // The positions buffer read back (n × 3), whichever path filled it.
  void read_positions(qpreduce::deform::Vertices* V) const;

  // Per-vertex colours for the categorical modes (n RGB triples in [0, 1]);
  // the deviation mode colours |p − rest| / deviation_scale in the shader.
  void set_colors(const std::vector<Eigen::Vector3f>& colors);
  // Vertices drawn as dots over the surface: slot 0 handles, slot 1 selection.
  void set_markers(int slot, const std::vector<unsigned>& vertices);

  struct Style {
    ColorMode mode = ColorMode::Clusters;
    float deviation_scale = 0.1f;  // |p − rest| mapped to the top of the colour ramp
    float marker_size = 6.0f;      // pixels
    Eigen::Vector3f background{0.95f, 0.95f, 0.96f};
  };
  // Clears and draws into the bound framebuffer (width × height pixels).
  void draw(const Camera& camera, int width, int height, const Style& style) const;

  Eigen::Index vertex_count() const { return n_; }

 private:
  Eigen::Index n_ = 0;
  GLsizei index_count_ = 0;
  GLuint vao_ = 0, empty_vao_ = 0;
  GLuint position_buf_ = 0, normal_buf_ = 0, color_buf_ = 0, rest_buf_ = 0, index_buf_ = 0;
  GLuint marker_buf_[2] = {0, 0};
  GLsizei marker_count_[2] = {0, 0};
  GLuint marker_vao_ = 0;
  // Reconstruction resources.
  GLuint basis_buf_ = 0, basis_tex_ = 0, w_buf_ = 0, w_tex_ = 0;
  GLuint position_tex_ = 0, ring_offset_buf_ = 0, ring_offset_tex_ = 0, ring_buf_ = 0, ring_tex_ = 0;
  GLint basis_texels_ = 0;  // q = ⌈p/4⌉ texels per basis row
  GLuint reconstruct_prog_ = 0, normals_prog_ = 0, shade_prog_ = 0, marker_prog_ = 0;
  // One-ring table (CSR): for vertex v, entries ring_offsets_[v] .. [v+1] are
  // the other two corners (b, c) of each incident triangle, counter-clockwise.
  std::vector<int> ring_offsets_, ring_;
  // CPU-path workspaces (sized once).
  std::vector<float> positions_, normals_;
  std::vector<float> w_padded_;

  void compute_normals_cpu();
};

}  // namespace qpr::viewer
