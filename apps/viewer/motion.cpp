#include "motion.h"

#include <qpreduce/util/atomic_file.h>
#include <qpreduce/deform/io/json_keys.h>

#include <fmt/format.h>
#include <nlohmann/json.hpp>

#include <algorithm>
#include <fstream>
#include <iterator>
#include <stdexcept>

namespace qpr::viewer {

using nlohmann::json;

void record_frame(const std::vector<ViewHandle>& handles, Eigen::Index vertex_count, HandleMotion* motion) {
  if (motion->frames.empty()) {
    motion->vertex_count = vertex_count;
    motion->handles.clear();
    for (const ViewHandle& h : handles) {
      HandleMotion::Handle m{h.name, {}, h.patch};
      if (h.patch < 0) m.vertices.assign(h.vertices.begin(), h.vertices.end());
      motion->handles.push_back(std::move(m));
    }
  }
  if (handles.size() != motion->handles.size())
    throw std::invalid_argument("record_frame: the handles changed during the recording");
  std::vector<Eigen::Matrix4d> frame;
  for (const ViewHandle& h : handles) frame.push_back(h.transform);
  motion->frames.push_back(std::move(frame));
}

void write_motion(const std::string& path, const HandleMotion& motion) {
  json j;
  j["format"] = "qpr-handle-motion";
  j["version"] = 1;
  j["vertex_count"] = motion.vertex_count;
  j["handles"] = json::array();
  for (const auto& h : motion.handles) {
    json e{{"name", h.name}};
    if (h.patch >= 0) e["patch"] = h.patch; else e["vertices"] = h.vertices;
    j["handles"].push_back(e);
  }
  j["frames"] = json::array();
  for (const auto& frame : motion.frames) {
    json f = json::array();
    for (const auto& T : frame) {
      json m = json::array();
      for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) m.push_back(T(r, c));
      f.push_back(m);
    }
    j["frames"].push_back(f);
  }
  qpreduce::write_file_atomically(path, j.dump(1) + "\n");
}

HandleMotion read_motion(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw std::runtime_error(path + ": cannot open the recording");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  qpreduce::deform::check_unique_json_keys(text, path);
  json j;
  try {
    j = json::parse(text);
  } catch (const std::exception& e) {
    throw std::runtime_error(path + ": not JSON: " + e.what());
  }
  auto fail = [&](const std::string& where, const std::string& what) {
    return std::runtime_error(fmt::format("{}: {}: {}", path, where, what));
  };
  if (!j.is_object() || j.value("format", "") != "qpr-handle-motion") throw fail("/format", "expected \"qpr-handle-motion\"");
  if (j.value("version", 0) != 1) throw fail("/version", "expected 1");
  HandleMotion m;
  if (!j.contains("vertex_count") || !j["vertex_count"].is_number_integer()) throw fail("/vertex_count", "expected an integer");
  m.vertex_count = j["vertex_count"].get<Eigen::Index>();
  if (!j.contains("handles") || !j["handles"].is_array()) throw fail("/handles", "expected an array");
  for (size_t i = 0; i < j["handles"].size(); ++i) {
    const json& h = j["handles"][i];
    const std::string where = fmt::format("/handles/{}", i);
    HandleMotion::Handle e;
    e.name = h.value("name", fmt::format("h{}", i));
    if (h.contains("patch") && h["patch"].is_number_integer()) {
      e.patch = h["patch"].get<int>();
    } else if (h.contains("vertices") && h["vertices"].is_array() && !h["vertices"].empty()) {
      for (const json& v : h["vertices"]) {
        if (!v.is_number_integer() || v.get<long>() < 0 || v.get<long>() >= m.vertex_count)
          throw fail(where + "/vertices", fmt::format("expected vertex indices in [0, {})", m.vertex_count));
        e.vertices.push_back(v.get<int>());
      }
    } else {
      throw fail(where, "expected \"vertices\" (a non-empty array) or \"patch\"");
    }
    m.handles.push_back(std::move(e));
  }
  if (!j.contains("frames") || !j["frames"].is_array()) throw fail("/frames", "expected an array");
  for (size_t f = 0; f < j["frames"].size(); ++f) {
    const json& frame = j["frames"][f];
    if (!frame.is_array() || frame.size() != m.handles.size())
      throw fail(fmt::format("/frames/{}", f), fmt::format("expected {} transforms", m.handles.size()));
    std::vector<Eigen::Matrix4d> Ts;
    for (size_t h = 0; h < frame.size(); ++h) {
      const json& t = frame[h];
      if (!t.is_array() || t.size() != 16) throw fail(fmt::format("/frames/{}/{}", f, h), "expected 16 numbers");
      Eigen::Matrix4d T;
      for (int k = 0; k < 16; ++k) {
        if (!t[k].is_number()) throw fail(fmt::format("/frames/{}/{}/{}", f, h, k), "expected a number");
        T(k / 4, k % 4) = t[k].get<double>();
      }
      if (!T.allFinite()) throw fail(fmt::format("/frames/{}/{}", f, h), "not finite");
      Ts.push_back(T);
    }
    m.frames.push_back(std::move(Ts));
  }
  return m;
}

// Replays motion frame f: the recorded handles must be the session's handles.
void apply_motion_frame(const HandleMotion& motion, size_t f, Session* session) {
  auto& handles = session->handles();
  const auto& frame = motion.frames[std::min(f, motion.frames.size() - 1)];
  for (size_t h = 0; h < handles.size() && h < frame.size(); ++h) handles[h].transform = frame[h];
}

// Replaces the session's handles by the recorded ones.
void handles_from_motion(const HandleMotion& motion, Session* session) {
  if (motion.vertex_count != session->rest().rows())
    throw std::runtime_error(fmt::format("the recording is for {} vertices, the mesh has {}", motion.vertex_count,
                                         session->rest().rows()));
  if (motion.frames.empty()) throw std::runtime_error("the recording has no frame");
  session->handles_from_scenario();
  std::vector<ViewHandle> patches;
  for (const ViewHandle& h : session->handles())
    if (h.patch >= 0) patches.push_back(h);
  session->handles().clear();
  for (const auto& h : motion.handles) {
    if (h.patch >= 0) {
      auto it = std::find_if(patches.begin(), patches.end(), [&](const ViewHandle& p) { return p.patch == h.patch; });
      if (it == patches.end()) throw std::runtime_error(fmt::format("the recording moves patch {}, which this scene does not prescribe", h.patch));
      session->handles().push_back(*it);
    } else {
      session->add_handle(h.vertices, h.name);
    }
  }
  apply_motion_frame(motion, 0, session);
}

}  // namespace qpr::viewer
