// .sel, .def, .id and .anim readers and the .id group helpers; the formats
// are described in handles_io.h.
#include "qpreduce/deform/io/handles_io.h"

#include "format_common.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

namespace qpreduce::deform {

namespace {

std::string name_of(const std::string& source) { return source.empty() ? "<in-memory data>" : source; }

void check_entry_count(const std::string& source, Index expected, Index got) {
  if (expected != got)
    detail::fail(name_of(source), 0,
                 fmt::format("expected {} entries (one per mesh vertex), got {}", expected, got));
}

// "# N vertices" in the comment lines before the first value, if any.
long long declared_vertex_count(const std::string& text) {
  std::size_t pos = 0;
  while (pos < text.size()) {
    const std::size_t eol = std::min(text.find('\n', pos), text.size());
    const std::string line = text.substr(pos, eol - pos);
    const std::size_t first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos) {
      pos = eol + 1;
      continue;
    }
    if (line[first] != '#') break;
    long long n = 0;
    char word[16] = {};
    if (std::sscanf(line.c_str() + first, "# %lld %15s", &n, word) == 2 && std::string(word) == "vertices") return n;
    pos = eol + 1;
  }
  return -1;
}

// Every token of the file as an integer in [lo, hi]; `range` explains the
// range in the error message.
std::vector<int> read_integers(const std::string& path, const std::string& text, const char* what, long long lo,
                               long long hi, const char* range) {
  detail::TextCursor cur(path, text);
  std::vector<int> values;
  for (std::string_view t = cur.next(); !t.empty(); t = cur.next()) {
    const long long v = cur.to_int(t, what);
    if (v < lo || v > hi) cur.fail(fmt::format("{} {} out of range ({})", what, v, range));
    values.push_back(static_cast<int>(v));
  }
  if (values.empty()) detail::fail(path, 0, "no entries (empty file)");
  return values;
}

// Groups are the ids in `labels`, in that order; other ids belong to none.
VertexGroups build_groups(const std::vector<int>& ids, std::vector<int> labels) {
  std::map<int, int> group;
  for (std::size_t g = 0; g < labels.size(); ++g) group[labels[g]] = static_cast<int>(g);
  VertexGroups out;
  out.label = std::move(labels);
  out.members.resize(out.label.size());
  out.group_of.assign(ids.size(), -1);
  for (std::size_t v = 0; v < ids.size(); ++v) {
    const auto it = group.find(ids[v]);
    if (it == group.end()) continue;
    out.group_of[v] = it->second;
    out.members[static_cast<std::size_t>(it->second)].push_back(static_cast<int>(v));
  }
  return out;
}

// The distinct ids >= min_id, ascending. With a `kind`, a negative id is an error.
std::vector<int> distinct_ids(const VertexIds& ids, int min_id, const char* kind) {
  std::vector<int> d;
  for (std::size_t v = 0; v < ids.ids.size(); ++v) {
    if (ids.ids[v] < 0 && kind != nullptr)
      detail::fail(name_of(ids.source), 0,
                   fmt::format("vertex {} has id {}; {} ids must be >= 0", v, ids.ids[v], kind));
    if (ids.ids[v] >= min_id) d.push_back(ids.ids[v]);
  }
  std::sort(d.begin(), d.end());
  d.erase(std::unique(d.begin(), d.end()), d.end());
  return d;
}

}  // namespace

// ---- .sel ----

Index Selection::count(SelRole role) const {
  return static_cast<Index>(std::count(roles.begin(), roles.end(), role));
}

std::vector<int> Selection::vertices(SelRole role) const {
  std::vector<int> out;
  for (std::size_t v = 0; v < roles.size(); ++v)
    if (roles[v] == role) out.push_back(static_cast<int>(v));
  return out;
}

void Selection::validate(Index vertex_count) const { check_entry_count(source, vertex_count, size()); }

Selection read_sel(const std::string& path) {
  const std::string text = detail::read_file(path);
  Selection sel;
  sel.source = path;
  for (int v : read_integers(path, text, "selection value", 0, 2, "expected 0 = fixed, 1 = free, 2 = handle"))
    sel.roles.push_back(static_cast<SelRole>(v));
  const long long declared = declared_vertex_count(text);
  if (declared >= 0 && declared != sel.size())
    detail::fail(path, 0, fmt::format("the header says {} vertices, the file has {} entries", declared, sel.size()));
  return sel;
}

// ---- .def ----

Eigen::Matrix4d read_def(const std::string& path) {
  const std::string text = detail::read_file(path);
  detail::TextCursor cur(path, text);
  Eigen::Matrix4d M;
  for (int i = 0; i < 4; ++i)
    for (int j = 0; j < 4; ++j) M(i, j) = cur.read_double("matrix entry (4 x 4, row-major)");
  if (!cur.at_end()) cur.fail(fmt::format("unexpected data after the 4 x 4 matrix ({})", detail::shown(cur.next())));
  // The files print the last row exactly ("0.000000 … 1.000000"), so compare exactly.
  if (M.row(3) != Eigen::RowVector4d(0.0, 0.0, 0.0, 1.0))
    detail::fail(path, 0, fmt::format("last row is ({} {} {} {}), expected 0 0 0 1 (an affine map)", M(3, 0),
                                      M(3, 1), M(3, 2), M(3, 3)));
  return M;
}

// ---- .id ----

void VertexIds::validate(Index vertex_count) const { check_entry_count(source, vertex_count, size()); }

VertexIds read_id(const std::string& path) {
  VertexIds ids;
  ids.source = path;
  ids.ids = read_integers(path, detail::read_file(path), "id", std::numeric_limits<int>::min(), std::numeric_limits<int>::max(),
                          "not a 32-bit integer");
  return ids;
}

VertexGroups linear_groups_from_ids(const VertexIds& ids) {
  return build_groups(ids.ids, distinct_ids(ids, 0, "linear-group"));
}

VertexGroups rotation_groups_from_ids(const VertexIds& ids) {
  const std::vector<int> all = distinct_ids(ids, std::numeric_limits<int>::min(), nullptr);
  const auto zero = std::lower_bound(all.begin(), all.end(), 0);
  std::vector<int> labels(zero, all.end());
  labels.insert(labels.end(), std::make_reverse_iterator(zero), all.rend());  // then −1, −2, …
  return build_groups(ids.ids, std::move(labels));
}

VertexGroups affine_patches_from_ids(const VertexIds& ids) {
  return build_groups(ids.ids, distinct_ids(ids, 1, "affine-patch"));
}

// ---- .anim ----

std::vector<int> HandleAnimation::handle_vertices() const {
  const Eigen::SparseMatrix<double, Eigen::RowMajor> W = weights;
  std::vector<int> out;
  for (Index h = 0; h < W.rows(); ++h) {
    Eigen::SparseMatrix<double, Eigen::RowMajor>::InnerIterator it(W, h);
    if (W.row(h).nonZeros() != 1 || it.value() != 1.0)
      detail::fail(name_of(source), 0, fmt::format("handle {} is not a single vertex with weight 1", h));
    out.push_back(static_cast<int>(it.col()));
  }
  return out;
}

void HandleAnimation::validate(Index count) const { check_entry_count(source, count, vertex_count()); }

HandleAnimation read_anim(const std::string& path) {
  const std::string text = detail::read_file(path);
  detail::TextCursor cur(path, text);
  long long header[7];
  const char* names[7] = {"frames", "handles", "weights_per_handle", "point_lists", "proj_mats", "model_mats",
                          "obj_mats"};
  for (int i = 0; i < 7; ++i) {
    header[i] = cur.read_int(names[i]);
    if (header[i] < 0) cur.fail(fmt::format("negative {} ({}) in header", names[i], header[i]));
  }
  const long long handles = header[1], n = header[2], lists = header[3];
  if (handles == 0) cur.fail("no handles (degenerate input)");
  if (n == 0 || n > std::numeric_limits<int>::max())
    cur.fail(fmt::format("weights_per_handle is {} (it must be the mesh's vertex count)", n));
  HandleAnimation anim;
  anim.source = path;
  anim.frames = header[0];
  std::vector<Eigen::Triplet<double, int>> triplets;
  for (long long h = 0; h < handles; ++h) {
    const std::size_t before = triplets.size();
    for (long long i = 0; i < n; ++i) {
      const double w = cur.read_double("handle weight");
      if (w != 0.0) triplets.emplace_back(static_cast<int>(h), static_cast<int>(i), w);
    }
    if (triplets.size() == before) cur.fail(fmt::format("handle {} has no nonzero weight", h));
  }
  anim.weights.resize(static_cast<Index>(handles), static_cast<Index>(n));
  anim.weights.setFromTriplets(triplets.begin(), triplets.end());
  for (long long f = 0; f < lists; ++f) {
    Vertices P(handles, 3);
    for (long long h = 0; h < handles; ++h)
      for (int k = 0; k < 3; ++k) P(h, k) = cur.read_double("target coordinate");
    anim.targets.push_back(std::move(P));
  }
  for (int kind = 0; kind < 3; ++kind) {
    std::vector<Eigen::Matrix4d>& out = kind == 0 ? anim.projection : kind == 1 ? anim.model : anim.object;
    for (long long m = 0; m < header[4 + kind]; ++m) {
      Eigen::Matrix4d M;
      for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) M(i, j) = cur.read_double(names[4 + kind]);
      out.push_back(M);
    }
  }
  if (!cur.at_end())
    cur.fail(fmt::format("unexpected data after the last of the header's items ({})", detail::shown(cur.next())));
  return anim;
}

}  // namespace qpreduce::deform
