// Deformer::save / Deformer::load — the precomputed model on disk.
//
// Layout (little-endian, version 6; docs/formats.md):
//   header   "QPREDUCEDEFORMER" (16 bytes), u32 version, u32 0x01020304 (byte order)
//   payload  records in a fixed order (below): integers as i64, labels as i32,
//            matrices as i64 rows, i64 cols, column-major f64 (or i32) data
//   trailer  u64 payload bytes, u32 CRC-32 (zlib) of the payload
//
// The payload keeps what precompute was given (rest positions, elements,
// patches, given clusters and groups, the options that change the result)
// and what it made (cluster labels, m, the float reconstruction basis P·B in
// row blocks, the patch unknowns' rows of B = [N UD], ‖B_j‖, H_r, BᵀD, M_N,
// M_U). The double basis B is not stored (nothing after precompute reads it):
// a process of a distributed precompute writes its rows of P·B as they come
// (Deformer::save with blocks), and no process holds B whole. A block is
// i64 first row, i64 rows, rows × p row-major f32 (f64 with double_basis); the blocks follow each
// other in row order and tile the 3n rows. load() first checks size and CRC over the whole file,
// then parses with every count bounded by the bytes left, then compares the
// stored inputs with the given ones, and only then replaces the session.
#include "qpreduce/deform/deformer/cache_file.h"
#include "qpreduce/deform/deformer/deformer.h"
#include "qpreduce/deform/io/io_error.h"

#include "state.h"

#include <qpreduce/util/atomic_file.h>
#include <qpreduce/util/timer.h>

#include <fmt/format.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <type_traits>

namespace qpreduce::deform {

namespace {

using detail::Model;

constexpr char kMagic[16] = {'Q', 'P', 'R', 'E', 'D', 'U', 'C', 'E', 'D', 'E', 'F', 'O', 'R', 'M', 'E', 'R'};
// 2: the model's name and parameters, Q kept or not; 3: the rotation step;
// 4: the float basis in row blocks instead of the double N, UD; 5: in the
// normalised frame; 6: the double_basis option (its rows in f64)
constexpr std::uint32_t kVersion = 6;
constexpr std::uint32_t kByteOrder = 0x01020304u;
constexpr std::streamoff kHeaderBytes = 16 + 4 + 4;
constexpr std::streamoff kTrailerBytes = 8 + 4;

// Running CRC-32 (crc32_z takes sizes beyond zlib's uInt). A null pointer
// would make zlib return the initial value instead, so empty ranges (an
// empty vector's data() may be null) are skipped.
std::uint32_t crc_update(std::uint32_t crc, const char* data, std::size_t bytes) {
  if (bytes == 0) return crc;
  return static_cast<std::uint32_t>(crc32_z(crc, reinterpret_cast<const Bytef*>(data), bytes));
}

class Writer {
 public:
  // Writes through a temporary file that close() renames over `path`
  // (AtomicFile): a failure leaves the earlier cache untouched, no temporary.
  explicit Writer(std::string path) : path_(std::move(path)), out_(path_) {
    out_.write(kMagic, sizeof kMagic);
    raw(kVersion);
    raw(kByteOrder);
    crc_ = static_cast<std::uint32_t>(crc32_z(0L, Z_NULL, 0));
  }

  template <typename T>
  void put(T value) {
    static_assert(std::is_arithmetic_v<T>);
    bytes(reinterpret_cast<const char*>(&value), sizeof(T));
  }
  template <typename Derived>
  void put_matrix(const Eigen::PlainObjectBase<Derived>& M) {
    using T = typename Derived::Scalar;
    put<std::int64_t>(M.rows());
    put<std::int64_t>(M.cols());
    const Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic> col_major = M;
    bytes(reinterpret_cast<const char*>(col_major.data()), sizeof(T) * static_cast<std::size_t>(M.size()));
  }
  // Row-major rows as they are in memory (a block of the float basis).
  template <typename Rows>
  void put_rows(const Rows& rows) {
    using Scalar = typename Rows::Scalar;
    bytes(reinterpret_cast<const char*>(rows.data()), sizeof(Scalar) * static_cast<std::size_t>(rows.size()));
  }
  template <typename T>
  void put_vector(const std::vector<T>& v) {
    put<std::int64_t>(static_cast<std::int64_t>(v.size()));
    bytes(reinterpret_cast<const char*>(v.data()), sizeof(T) * v.size());
  }

  void close() {
    raw(static_cast<std::uint64_t>(payload_));
    raw(crc_);
    out_.commit();
  }

 private:
  template <typename T>
  void raw(T value) {
    out_.write(reinterpret_cast<const char*>(&value), sizeof(T));
  }
  void bytes(const char* data, std::size_t n) {
    out_.write(data, static_cast<std::streamsize>(n));
    crc_ = crc_update(crc_, data, n);
    payload_ += n;
  }

  std::string path_;
  AtomicFile out_;
  std::uint32_t crc_ = 0;
  std::uint64_t payload_ = 0;
};

class Reader {
 public:
  // Opens `path`, checks header, size and CRC; then reads the payload.
  explicit Reader(std::string path) : path_(std::move(path)), in_(path_, std::ios::binary) {
    if (!in_) throw IoError(path_, 0, "cannot open (missing file or no permission)");
    in_.seekg(0, std::ios::end);
    const std::streamoff size = in_.tellg();
    in_.seekg(0);
    if (size < kHeaderBytes + kTrailerBytes) {
      throw IoError(path_, 0, fmt::format("truncated: {} bytes is shorter than a cache header", size));
    }
    char magic[16];
    in_.read(magic, sizeof magic);
    if (std::memcmp(magic, kMagic, sizeof magic) != 0) {
      throw IoError(path_, 0, "not a qpreduce deformer cache (wrong magic bytes)");
    }
    const auto version = raw<std::uint32_t>();
    const auto order = raw<std::uint32_t>();
    if (order != kByteOrder) throw IoError(path_, 0, "written on a machine with another byte order");
    if (version != kVersion) {
      throw IoError(path_, 0,
                    fmt::format("format version {} (this build reads version {}); precompute again", version, kVersion));
    }
    in_.seekg(size - kTrailerBytes);
    const auto payload = raw<std::uint64_t>();
    const auto crc = raw<std::uint32_t>();
    const auto expected = static_cast<std::uint64_t>(size - kHeaderBytes - kTrailerBytes);
    if (payload != expected) {
      throw IoError(path_, 0,
                    fmt::format("truncated or padded: the trailer says {} payload bytes, the file holds {}", payload,
                                expected));
    }
    // CRC over the whole payload before anything is parsed.
    in_.seekg(kHeaderBytes);
    std::vector<char> chunk(1 << 20);
    std::uint32_t got = static_cast<std::uint32_t>(crc32_z(0L, Z_NULL, 0));
    for (std::uint64_t left = payload; left > 0;) {
      const std::size_t n = static_cast<std::size_t>(std::min<std::uint64_t>(left, chunk.size()));
      in_.read(chunk.data(), static_cast<std::streamsize>(n));
      if (!in_) throw IoError(path_, 0, "read failed");
      got = crc_update(got, chunk.data(), n);
      left -= n;
    }
    if (got != crc) {
      throw IoError(path_, 0, fmt::format("corrupted: CRC-32 {:08x} does not match the stored {:08x}", got, crc));
    }
    in_.seekg(kHeaderBytes);
    left_ = payload;
  }

  template <typename T>
  T get(const char* what) {
    T value;
    bytes(reinterpret_cast<char*>(&value), sizeof(T), what);
    return value;
  }
  Index get_count(const char* what, std::uint64_t element_bytes) {
    const auto count = get<std::int64_t>(what);
    if (count < 0 || static_cast<std::uint64_t>(count) > left_ / std::max<std::uint64_t>(element_bytes, 1)) {
      throw IoError(path_, 0, fmt::format("{}: count {} does not fit in the file", what, count));
    }
    return static_cast<Index>(count);
  }
  template <typename T, int R, int C, int O>
  void get_matrix(const char* what, Eigen::Matrix<T, R, C, O>* M) {
    const Index rows = get_count(what, 0);
    const Index cols = get_count(what, 0);
    if (cols > 0 && static_cast<std::uint64_t>(rows) > left_ / sizeof(T) / static_cast<std::uint64_t>(cols)) {
      throw IoError(path_, 0, fmt::format("{}: {} × {} entries do not fit in the file", what, rows, cols));
    }
    if ((C != Eigen::Dynamic && cols != C) || (R != Eigen::Dynamic && rows != R)) {
      throw IoError(path_, 0, fmt::format("{}: unexpected shape {} × {}", what, rows, cols));
    }
    Eigen::Matrix<T, Eigen::Dynamic, Eigen::Dynamic> col_major(rows, cols);
    bytes(reinterpret_cast<char*>(col_major.data()), sizeof(T) * static_cast<std::size_t>(rows * cols), what);
    if constexpr (std::is_floating_point_v<T>) {
      if (!col_major.allFinite()) throw IoError(path_, 0, fmt::format("{}: NaN or infinite entries", what));
    }
    *M = col_major;
  }
  // The basis, rows × cols, from its row blocks (see the layout): f32, or
  // f64 for a double_basis deformer.
  template <typename Rows>
  void get_row_blocks(const char* what, Index rows, Index cols, Rows* out) {
    using Scalar = typename Rows::Scalar;
    out->resize(rows, cols);
    for (Index covered = 0; covered < rows;) {
      const auto first = get<std::int64_t>(what);
      const auto count = get<std::int64_t>(what);
      if (first != covered || count < 1 || count > rows - covered) {
        throw IoError(path_, 0, fmt::format("{}: a block of rows [{}, {}) where row {} of {} was due", what, first,
                                            first + count, covered, rows));
      }
      if (cols > 0 && static_cast<std::uint64_t>(count) > left_ / sizeof(Scalar) / static_cast<std::uint64_t>(cols)) {
        throw IoError(path_, 0, fmt::format("{}: {} × {} entries do not fit in the file", what, count, cols));
      }
      auto block = out->middleRows(covered, count);
      bytes(reinterpret_cast<char*>(block.data()), sizeof(Scalar) * static_cast<std::size_t>(count * cols), what);
      if (!block.allFinite()) throw IoError(path_, 0, fmt::format("{}: NaN or infinite entries", what));
      covered += count;
    }
  }
  template <typename T>
  std::vector<T> get_vector(const char* what) {
    std::vector<T> v(static_cast<std::size_t>(get_count(what, sizeof(T))));
    bytes(reinterpret_cast<char*>(v.data()), sizeof(T) * v.size(), what);
    return v;
  }
  void expect_end() {
    if (left_ != 0) throw IoError(path_, 0, fmt::format("{} unexpected bytes after the last record", left_));
  }
  [[noreturn]] void mismatch(const std::string& what) const {
    throw IoError(path_, 0, "made from other inputs: " + what + "; precompute again (or delete the cache file)");
  }
  const std::string& path() const { return path_; }

 private:
  template <typename T>
  T raw() {
    T value;
    in_.read(reinterpret_cast<char*>(&value), sizeof(T));
    if (!in_) throw IoError(path_, 0, "read failed");
    return value;
  }
  void bytes(char* data, std::size_t n, const char* what) {
    if (n > left_) throw IoError(path_, 0, fmt::format("truncated inside {}", what));
    in_.read(data, static_cast<std::streamsize>(n));
    if (!in_) throw IoError(path_, 0, fmt::format("read failed inside {}", what));
    left_ -= n;
  }

  std::string path_;
  std::ifstream in_;
  std::uint64_t left_ = 0;
};

// The options that change what precompute makes, as (name, value) pairs in
// a fixed order: the model's parameters, then the deformer's. Runtime
// options (iterations, global_rotation) are not here.
std::vector<std::pair<std::string, double>> result_options(const DeformationModel& model, const DeformerOptions& o) {
  std::vector<std::pair<std::string, double>> opts = model.parameters();
  const std::vector<std::pair<std::string, double>> rest = {
          {"rotational_proxies", static_cast<double>(o.rotational_proxies)},
          {"linear_proxies", static_cast<double>(o.linear_proxies)},
          {"clustering.kmeans.seed", static_cast<double>(o.clustering.kmeans.seed)},
          {"clustering.kmeans.max_iterations", static_cast<double>(o.clustering.kmeans.max_iterations)},
          {"clustering.kmeans.tolerance", o.clustering.kmeans.tolerance},
          {"clustering.spectral.eigenvectors", static_cast<double>(o.clustering.spectral.eigenvectors)},
          {"clustering.spectral.shift_scale", o.clustering.spectral.shift_scale},
          {"subspace.reduced_lift_tolerance", o.subspace.reduced_lift_tolerance},
          {"rotation_fit", o.rotation_fit == ClusterRotationFit::Exact ? 0.0 : 1.0},
          {"double_basis", o.double_basis ? 1.0 : 0.0}};
  opts.insert(opts.end(), rest.begin(), rest.end());
  return opts;
}

std::vector<int> name_codes(const std::string& name) { return std::vector<int>(name.begin(), name.end()); }

std::vector<std::int64_t> flatten(const std::vector<std::vector<Index>>& groups) {
  std::vector<std::int64_t> flat;
  for (const auto& g : groups) {
    flat.push_back(static_cast<std::int64_t>(g.size()));
    flat.insert(flat.end(), g.begin(), g.end());
  }
  return flat;
}

std::vector<int> patch_codes(const std::vector<PatchType>& types) {
  std::vector<int> codes;
  for (PatchType t : types) codes.push_back(static_cast<int>(t));
  return codes;
}

template <typename M>
void compare_matrix(const Reader& r, const char* what, const M& stored, const M& given) {
  if (stored.rows() != given.rows()) {
    r.mismatch(fmt::format("{} has {} rows in the cache, {} given", what, stored.rows(), given.rows()));
  }
  for (Index i = 0; i < stored.rows(); ++i) {
    if (stored.row(i) != given.row(i)) r.mismatch(fmt::format("{} differ (first at row {})", what, i));
  }
}

template <typename T>
void compare_vector(const Reader& r, const char* what, const std::vector<T>& stored, const std::vector<T>& given) {
  if (stored.size() != given.size()) {
    r.mismatch(fmt::format("{} has {} entries in the cache, {} given", what, stored.size(), given.size()));
  }
  for (std::size_t i = 0; i < stored.size(); ++i) {
    if (stored[i] != given[i]) r.mismatch(fmt::format("{} differ (first at entry {})", what, i));
  }
}

// Reads the stored inputs and compares them with the given ones (as
// set_topology made them, with the internal patch of unreferenced vertices);
// sets the energy model and whether Q is kept.
void read_inputs(Reader& r, const std::string& path, const DeformableMesh& mesh, const DeformerOptions& options,
                 Model& model) {
  Vertices V;
  r.get_matrix("rest positions", &V);
  if (V.rows() != model.n) r.mismatch(fmt::format("the cache has {} vertices, the mesh {}", V.rows(), model.n));
  compare_matrix(r, "rest positions", V, model.rest);
  Triangles F;
  Tetrahedra T;
  r.get_matrix("triangles", &F);
  r.get_matrix("tetrahedra", &T);
  compare_matrix(r, "triangles", F, mesh.F);
  compare_matrix(r, "tetrahedra", T, mesh.T);
  compare_vector(r, "given rotational clusters", r.get_vector<int>("given clusters"), mesh.clusters);
  compare_vector(r, "given linear proxy groups", r.get_vector<std::int64_t>("given groups"),
                 flatten(mesh.linear.groups));
  compare_vector(r, "patch of each vertex", r.get_vector<int>("patches"), model.patch_of_vertex);
  compare_vector(r, "patch types", r.get_vector<int>("patch types"), patch_codes(model.patch_types));
  model.energy_model = options.resolve_model();
  const std::vector<int> stored_name = r.get_vector<int>("model name");
  if (stored_name != name_codes(model.energy_model->name())) {
    r.mismatch(fmt::format("the cache was made with the model \"{}\", \"{}\" given",
                           std::string(stored_name.begin(), stored_name.end()), model.energy_model->name()));
  }
  const auto opts = result_options(*model.energy_model, options);
  const Index stored_opts = r.get_count("options", sizeof(double));
  if (stored_opts != static_cast<Index>(opts.size())) {
    r.mismatch(fmt::format("{} stored options, {} expected", stored_opts, opts.size()));
  }
  for (const auto& [name, value] : opts) {
    const double stored = r.get<double>(name.c_str());
    if (stored != value) r.mismatch(fmt::format("option {} is {} in the cache, {} given", name, stored, value));
  }
  const auto keep_q = r.get<std::int64_t>("Q kept");
  if (keep_q != 0 && keep_q != 1) throw IoError(path, 0, fmt::format("invalid Q-kept flag {}", keep_q));
  if (keep_q == 1) model.keep_rotation_corrections();
}

// Reads what precompute made: the clusters, m, the subspace and the reduced
// operators, checking their sizes; restores the solver.
void read_results(Reader& r, const std::string& path, const DeformableMesh& mesh, const DeformerOptions& options,
                  Model& model) {
  std::vector<int> labels = r.get_vector<int>("cluster labels");
  const auto d = r.get<std::int64_t>("cluster count");
  const auto m = r.get<std::int64_t>("linear proxy count");
  if (d < 1 || m < 0) throw IoError(path, 0, fmt::format("invalid proxy counts d = {}, m = {}", d, m));
  try {
    model.set_clusters(std::move(labels), d);
    model.find_rigid_clusters(mesh.T);
  } catch (const std::invalid_argument& e) {
    throw IoError(path, 0, e.what());
  }
  model.m = m;
  model.nx = 3 * model.m + 12 * model.s;
  const Index p = model.nx + 9 * model.d;
  const Index nine_d = 9 * model.d;
  const auto rows = r.get<std::int64_t>("basis rows");
  const auto cols = r.get<std::int64_t>("basis columns");
  if (rows != 3 * model.n || cols != p) {
    throw IoError(path, 0, fmt::format("inconsistent sizes: basis {}×{} for n = {}, p = {}", rows, cols, model.n, p));
  }
  if (model.double_basis) {
    r.get_row_blocks("reconstruction basis", 3 * model.n, p, &model.basis_double);
  } else {
    r.get_row_blocks("reconstruction basis", 3 * model.n, p, &model.basis);
  }
  model.basis_first = 0;
  Matrix<double> patch_rows, norms, Hr, BtD;
  r.get_matrix("patch rows", &patch_rows);
  r.get_matrix("basis norms", &norms);
  r.get_matrix("H_r", &Hr);
  r.get_matrix("BᵀD", &BtD);
  r.get_matrix("M_N", &model.MN);
  r.get_matrix("M_U", &model.MU);
  r.expect_end();
  if (patch_rows.rows() != 12 * model.s || patch_rows.cols() != p || norms.rows() != p || norms.cols() != 1 ||
      model.MN.rows() != nine_d || model.MN.cols() != model.nx || model.MU.rows() != nine_d ||
      model.MU.cols() != nine_d) {
    throw IoError(path, 0,
                  fmt::format("inconsistent sizes: patch rows {}×{}, basis norms {}×{}, M_N {}×{}, M_U {}×{} for "
                              "s = {}, p = {}",
                              patch_rows.rows(), patch_rows.cols(), norms.rows(), norms.cols(), model.MN.rows(),
                              model.MN.cols(), model.MU.rows(), model.MU.cols(), model.s, p));
  }
  model.patch_rows = patch_rows;
  try {
    SubspaceOptions sub = options.subspace;
    sub.prepare_constraint_path = false;  // as subspace_options (precompute.cpp)
    model.solver.restore_without_basis(model.nu, model.nx, norms.col(0), std::move(Hr), std::move(BtD), sub);
  } catch (const std::invalid_argument& e) {
    throw IoError(path, 0, e.what());
  }
}

}  // namespace

bool is_deformer_cache(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) return false;
  std::ifstream in(path, std::ios::binary);
  char magic[sizeof kMagic];
  return in.read(magic, sizeof magic) && std::memcmp(magic, kMagic, sizeof magic) == 0;
}

bool may_replace_with_cache(const std::string& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status) || !std::filesystem::is_regular_file(status)) return true;
  return std::filesystem::file_size(path, ec) == 0 || is_deformer_cache(path);
}

namespace {

// The blocks `next` gives (Rows: f32 or f64 row-major), checked to tile the
// 3n × p basis in row order, as records into w.
template <typename Rows, typename Next>
void put_basis_blocks(Writer& w, Index rows, Index p, Next next) {
  Rows block;
  Index covered = 0, first = 0;
  while (covered < rows && next(&first, &block)) {
    if (block.rows() == 0) continue;
    if (first != covered || block.rows() > rows - covered || block.cols() != p) {
      throw std::invalid_argument(
          fmt::format("Deformer::save: a basis block of rows [{}, {}) × {} columns where row {} of {} (× {}) was due",
                      first, first + block.rows(), block.cols(), covered, rows, p));
    }
    if (!block.allFinite()) {
      throw std::invalid_argument(fmt::format("Deformer::save: the basis block at row {} holds NaN or Inf", first));
    }
    w.put<std::int64_t>(first);
    w.put<std::int64_t>(block.rows());
    w.put_rows(block);
    covered += block.rows();
  }
  if (covered != rows) {
    throw std::invalid_argument(fmt::format("Deformer::save: the basis blocks end at row {} of {}", covered, rows));
  }
}

// Blocks of 4,096 rows of a whole basis B: a copy of one block at a time.
template <typename Rows>
auto whole_basis_blocks(const Rows& B) {
  return [&B, next_row = Index(0)](Index* first, Rows* rows) mutable {
    constexpr Index kBlockRows = 4096;
    if (next_row >= B.rows()) return false;
    const Index count = std::min(kBlockRows, B.rows() - next_row);
    *first = next_row;
    *rows = B.middleRows(next_row, count);
    next_row += count;
    return true;
  };
}

// The whole cache of session `st` at `path`; put_basis(w, 3n, p) writes the
// basis records. (State is deduced: Deformer's own type.)
template <typename State, typename PutBasis>
void write_cache(const State& st, const std::string& path, const PutBasis& put_basis) {
  if (!may_replace_with_cache(path)) {
    throw std::invalid_argument(fmt::format(
        "Deformer::save: {} exists and is not a qpreduce deformer cache; refusing to replace it "
        "(remove it or choose another path)",
        path));
  }
  const Model& model = st.model;
  const Index rows = 3 * model.n, p = model.nx + 9 * model.d;
  try {
    Writer w(path);
    // Inputs.
    w.put_matrix(model.rest);
    w.put_matrix(st.inputs.F);
    w.put_matrix(st.inputs.T);
    w.put_vector(st.inputs.clusters);
    w.put_vector(flatten(st.inputs.groups));
    w.put_vector(model.patch_of_vertex);
    w.put_vector(patch_codes(model.patch_types));
    w.put_vector(name_codes(model.energy_model->name()));
    const auto opts = result_options(*model.energy_model, st.inputs.options);
    w.put<std::int64_t>(static_cast<std::int64_t>(opts.size()));
    for (const auto& [name, value] : opts) w.put(value);
    w.put<std::int64_t>(model.keep_q ? 1 : 0);
    // What precompute made.
    w.put_vector(model.clusters);
    w.put<std::int64_t>(model.d);
    w.put<std::int64_t>(model.m);
    w.put<std::int64_t>(rows);
    w.put<std::int64_t>(p);
    put_basis(w, rows, p);
    Matrix<double> norms = model.solver.basis_norms();
    w.put_matrix(Matrix<double>(model.patch_rows));
    w.put_matrix(norms);
    w.put_matrix(model.solver.reduced_hessian());
    w.put_matrix(model.solver.reduced_linear_map());
    w.put_matrix(model.MN);
    w.put_matrix(model.MU);
    w.close();
  } catch (const FileError& e) {
    throw IoError(path, 0, e.problem());
  }
}

}  // namespace

void Deformer::save(const std::string& path) const {
  if (!state_->ready) throw std::invalid_argument("Deformer::save: call precompute (or load) first");
  const detail::Model& model = state_->model;
  if (!model.whole_basis()) {
    throw std::invalid_argument(fmt::format(
        "Deformer::save: this deformer holds rows [{}, {}) of the {}-row reconstruction basis (precompute_part); "
        "save(path, blocks) with every part's rows",
        model.basis_first, model.basis_first + model.basis_count(), 3 * model.n));
  }
  if (model.double_basis) {
    write_cache(*state_, path, [&](Writer& w, Index rows, Index p) {
      put_basis_blocks<detail::RowMatrixD>(w, rows, p, whole_basis_blocks(model.basis_double));
    });
    return;
  }
  save(path, whole_basis_blocks(model.basis));
}

void Deformer::save(const std::string& path, const BasisBlocks& next) const {
  const State& st = *state_;
  if (!st.ready) throw std::invalid_argument("Deformer::save: call precompute (or load) first");
  if (!next) throw std::invalid_argument("Deformer::save: no basis blocks given");
  if (st.model.double_basis) {
    throw std::invalid_argument(
        "Deformer::save: this deformer keeps its basis in double (DeformerOptions::double_basis); float blocks "
        "cannot stand for it: save(path) writes it");
  }
  write_cache(st, path, [&](Writer& w, Index rows, Index p) { put_basis_blocks<BasisRows>(w, rows, p, next); });
}

PrecomputeSummary Deformer::load(const std::string& path, const DeformableMesh& mesh,
                                 const DeformerOptions& options) {
  std::string why;
  if (!options.is_valid(&why)) throw std::invalid_argument("DeformerOptions: " + why);
  const Timer total;
  Reader r(path);
  auto st = std::make_unique<State>();
  Model& model = st->model;
  model.frame = normalization_of(mesh.V);
  const DeformableMesh local = normalised(mesh, model.frame);
  model.set_topology(local);
  st->inputs = {mesh.F, mesh.T, mesh.clusters, mesh.linear.groups, options};
  model.double_basis = options.double_basis;
  read_inputs(r, path, local, options, model);
  read_results(r, path, local, options, model);
  st->finish(options);
  state_ = std::move(st);
  reset_pose();

  PrecomputeSummary summary;
  summary.status = Status::Success;
  summary.message = "loaded from " + path;
  detail::describe(state_->model, &summary);
  summary.total_seconds = total.seconds();
  return summary;
}

}  // namespace qpreduce::deform
