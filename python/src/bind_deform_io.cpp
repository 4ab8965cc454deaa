// qpreduce.deform, the file side (deform/io/*) and the shapes and references:
// mesh readers and writers with (V, F) / (V, T) NumPy arrays, .sel/.def,
// JSON scenes and the scenarios built from them, the built-in shapes, and the
// full-space references (reference/reference.h). Readers and writers release
// the GIL; IoError (a file problem) is qpreduce.deform.IoError, an OSError.
#include <pybind11/stl.h>
#include <qpreduce/deform/io/handles_io.h>
#include <qpreduce/deform/io/mesh_io.h>
#include <qpreduce/deform/io/scenario.h>
#include <qpreduce/deform/io/scene.h>
#include <qpreduce/deform/io/tet_io.h>
#include <qpreduce/deform/mesh/mesh_check.h>
#include <qpreduce/deform/mesh/shapes.h>
#include <qpreduce/deform/reference/reference.h>

#include "arguments.h"
#include "bindings.h"
#include "fields.h"

namespace qpreduce::python {

namespace {

using namespace qpreduce::deform;

Vertices vertices_arg(const char* name, py::handle V) {
  return py::module_::import("qpreduce._convert")
      .attr("as_rows")(name, V, py::make_tuple(3), "n", "float64")
      .cast<Vertices>();
}

template <typename Elements>
Elements elements_arg(const char* name, py::handle E) {
  return py::module_::import("qpreduce._convert")
      .attr("as_rows")(name, E, py::make_tuple(static_cast<int>(Elements::ColsAtCompileTime)), "m", "int32")
      .template cast<Elements>();
}

// Runs `read` with the GIL released; returns its result.
template <typename F>
auto without_gil(F&& f) {
  py::gil_scoped_release release;
  return f();
}

void bind_mesh_io(py::module_& m) {
  m.def(
      "read_mesh",
      [](const std::string& path) {
        const TriangleMesh mesh = without_gil([&] { return read_triangle_mesh(path); });
        return py::make_tuple(mesh.V, mesh.F);
      },
      py::arg("path"),
      "read_mesh(path) -> (V, F)\n\nA triangle mesh from .obj, .off or .ply: V (n, 3) float64, F (m, 3) int32,\n"
      "0-based (polygons fan-triangulated). Raises IoError naming the file and line.");
  m.def(
      "write_mesh",
      [](const std::string& path, py::handle V, py::handle F) {
        TriangleMesh mesh{vertices_arg("V", V), elements_arg<Triangles>("F", F)};
        py::gil_scoped_release release;
        write_triangle_mesh(path, mesh);
      },
      py::arg("path"), py::arg("V"), py::arg("F"),
      "write_mesh(path, V, F)\n\nWrites .obj, .off or .ply (ASCII) by the extension; V (n, 3), F (m, 3) integers.\n"
      "Doubles round-trip exactly. Raises ValueError on bad indices/NaN, IoError when it cannot write.");
  m.def(
      "read_tet_mesh",
      [](const std::string& path, bool boundary) {
        const TetMesh mesh = without_gil([&] { return read_tet_mesh(path); });
        return boundary ? py::make_tuple(mesh.V, mesh.T, mesh.F) : py::make_tuple(mesh.V, mesh.T);
      },
      py::arg("path"), py::arg("boundary") = false,
      "read_tet_mesh(path, boundary=False) -> (V, T) or (V, T, F)\n\nA tetrahedral mesh from MEDIT .mesh or TetGen .node/.ele: V (n, 3) float64,\n"
      "T (m, 4) int32; with boundary=True also the file's boundary triangles F (k, 3) (empty when it has none).");
  m.def(
      "write_tet_mesh",
      [](const std::string& path, py::handle V, py::handle T, py::handle F) {
        TetMesh mesh{vertices_arg("V", V), elements_arg<Tetrahedra>("T", T), Triangles(0, 3)};
        if (!F.is_none()) mesh.F = elements_arg<Triangles>("F", F);
        py::gil_scoped_release release;
        write_tet_mesh(path, mesh);
      },
      py::arg("path"), py::arg("V"), py::arg("T"), py::arg("F") = py::none(),
      "write_tet_mesh(path, V, T, F=None)\n\nWrites MEDIT .mesh or TetGen .node by the extension.");
  m.def(
      "read_sel",
      [](const std::string& path) {
        const Selection sel = without_gil([&] { return read_sel(path); });
        std::vector<int> roles(sel.roles.size());
        for (size_t i = 0; i < roles.size(); ++i) roles[i] = static_cast<int>(sel.roles[i]);
        return py::array_t<int>(static_cast<py::ssize_t>(roles.size()), roles.data());
      },
      py::arg("path"),
      "read_sel(path) -> roles (n,) int32\n\nA Botsch–Sorkine .sel: 0 fixed, 1 free, 2 handle per vertex.");
  m.def(
      "read_def", [](const std::string& path) { return Eigen::Matrix4d(read_def(path)); }, py::arg("path"),
      "read_def(path) -> (4, 4)\n\nA Botsch–Sorkine .def: the handle's affine map (column vectors).");
  auto shapes = m.def_submodule("shapes", "Procedural meshes (mesh/shapes.h), no files needed.");
  shapes.def(
      "capped_cylinder",
      [](double radius, double height, Index around, Index rings) {
        const TriangleMesh mesh = shapes::capped_cylinder(radius, height, around, rings);
        return py::make_tuple(mesh.V, mesh.F);
      },
      py::arg("radius") = 1.0, py::arg("height") = 12.0, py::arg("around") = 60, py::arg("rings") = 80,
      "capped_cylinder(radius=1, height=12, around=60, rings=80) -> (V, F)\n\n"
      "The closed cylinder of `qpr demo` (4,802 vertices by default) around the z axis, z ∈ [0, height].");
  shapes.def(
      "box_tets",
      [](double sx, double sy, double sz, Index nx, Index ny, Index nz) {
        const TetMesh mesh = shapes::box_tets(sx, sy, sz, nx, ny, nz);
        return py::make_tuple(mesh.V, mesh.T);
      },
      py::arg("sx"), py::arg("sy"), py::arg("sz"), py::arg("nx"), py::arg("ny"), py::arg("nz"),
      "box_tets(sx, sy, sz, nx, ny, nz) -> (V, T)\n\nThe box [0,sx]×[0,sy]×[0,sz] in nx·ny·nz cubes of six tets.");
}

void bind_scenarios(py::module_& m) {
  py::class_<Scenario>(m, "Scenario",
                       "A model, its handles and the targets of every frame (io/scenario.h), from .sel/.def or\n"
                       "a JSON scene. Use: Deformer(s.model, s.options(opts)); set_handles(s.handles,\n"
                       "options=s.constraints); frame(s.frames[i]).")
      .def_readwrite("model", &Scenario::model, "The Model (mesh, clusters, patches).")
      .def_readwrite("handles", &Scenario::handles, "Handles.")
      .def_readwrite("frames", &Scenario::frames, "List of HandleTargets, one per frame.")
      .def_readwrite("constraints", &Scenario::constraints, "ConstraintOptions (hard, or soft from a scene).")
      .def(
          "options",
          [](const Scenario& s, py::handle base) {
            DeformerOptions options = options_arg<DeformerOptions>("base", base);
            apply_scenario_options(s, &options);
            return options;
          },
          py::arg("base") = py::none(),
          "options(base=None) -> DeformerOptions: base with the scene's overrides (α, β, γ, model, ψ, rounds).")
      .def("__repr__", [](const Scenario& s) {
        return "Scenario(n=" + std::to_string(s.model.V.rows()) +
               ", points=" + std::to_string(s.handles.points.size()) +
               ", patches=" + std::to_string(s.handles.patches.size()) + ", frames=" + std::to_string(s.frames.size()) +
               ")";
      });
  m.def(
      "sel_def_scenario",
      [](py::handle V, py::handle F, py::handle sel, py::handle def, int frames) {
        Scenario sc;
        const Vertices rest = vertices_arg("V", V);
        Selection selection;
        if (py::isinstance<py::str>(sel)) {
          selection = read_sel(sel.cast<std::string>());
        } else {
          const auto roles = py::module_::import("qpreduce._convert")
                                 .attr("as_labels")("sel", sel, rest.rows(), "n")
                                 .cast<std::vector<int>>();
          for (const int r : roles) {
            if (r < 0 || r > 2) throw py::value_error("sel: roles must be 0 (fixed), 1 (free) or 2 (handle)");
            selection.roles.push_back(static_cast<SelRole>(r));
          }
        }
        const Eigen::Matrix4d M = py::isinstance<py::str>(def)
                                      ? read_def(def.cast<std::string>())
                                      : Eigen::Matrix4d(dense_arg<double>("def", def, {4, "4"}, {4, "4"}));
        sc = scenario_from_sel_def(rest, selection, M, frames);
        sc.model.F = elements_arg<Triangles>("F", F);
        return sc;
      },
      py::arg("V"), py::arg("F"), py::arg("sel"), py::arg("def"), py::arg("frames") = 1,
      "sel_def_scenario(V, F, sel, def, frames=1) -> Scenario\n\n"
      "A Botsch–Sorkine scenario: sel a .sel path or (n,) roles (0 fixed, 1 free, 2 handle), def a\n"
      ".def path or (4, 4) matrix. A Fixed patch and an Affine handle patch moved by def over\n"
      "`frames` frames from rest.");
  m.def(
      "anim_scenario",
      [](py::handle V, py::handle F, const std::string& path) {
        const Vertices rest = vertices_arg("V", V);
        Triangles triangles = elements_arg<Triangles>("F", F);
        Scenario sc = without_gil([&] { return scenario_from_anim(rest, read_anim(path)); });
        sc.model.F = std::move(triangles);
        return sc;
      },
      py::arg("V"), py::arg("F"), py::arg("path"),
      "anim_scenario(V, F, path) -> Scenario\n\n"
      "The paper demo's .anim: one point handle per animation handle (its weighted vertices), one frame\n"
      "per recorded point list. V (n, 3), F (m, 3); IoError when the file does not fit the mesh.");
  m.def(
      "read_scene",
      [](const std::string& path) { return without_gil([&] { return scenario_from_scene(read_scene(path)); }); },
      py::arg("path"),
      "read_scene(path) -> Scenario\n\nOur JSON scene (docs/formats.md): mesh, handles, patches, proxies, energy.");
}

// diagnose_mesh's summary as a dict (its fields; findings as dicts).
py::dict check_dict(const MeshCheckSummary& s) {
  py::list findings;
  for (const MeshFinding& f : s.findings)
    findings.append(py::dict(py::arg("defect") = to_string(f.defect), py::arg("severity") = to_string(f.severity),
                             py::arg("count") = f.count, py::arg("item") = f.item, py::arg("first") = f.first,
                             py::arg("message") = f.message));
  return py::dict(py::arg("status") = to_string(s.verdict), py::arg("vertices") = s.vertices,
                  py::arg("elements") = s.elements, py::arg("corners") = s.corners,
                  py::arg("box_min") = Eigen::Vector3d(s.box_min), py::arg("box_max") = Eigen::Vector3d(s.box_max),
                  py::arg("diagonal") = s.diagonal, py::arg("shortest_edge") = s.shortest_edge,
                  py::arg("longest_edge") = s.longest_edge, py::arg("worst_quality") = s.worst_quality,
                  py::arg("components") = s.components, py::arg("anchors_checked") = s.anchors_checked,
                  py::arg("findings") = findings, py::arg("seconds") = s.seconds);
}

void bind_mesh_check(py::module_& m) {
  m.def(
      "diagnose_mesh",
      [](py::handle V, py::handle E, py::handle anchored, double near_degenerate_quality, double duplicate_distance,
         double far_distance, Index max_listed) {
        // V may hold NaN or infinities: they are findings here, not argument errors.
        const auto v = py::array_t<double, py::array::c_style | py::array::forcecast>::ensure(V);
        if (!v || v.ndim() != 2 || v.shape(1) != 3)
          throw py::value_error("V: expected a real array of shape (n, 3)");
        const Vertices rest = Eigen::Map<const Vertices>(v.data(), v.shape(0), 3);
        const auto elements = py::module_::import("qpreduce._convert")
                                  .attr("as_rows")("E", E, py::make_tuple(3, 4), "m", "int32")
                                  .cast<Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>();
        std::vector<char> held;
        if (!anchored.is_none()) {
          const auto a = py::array_t<bool, py::array::c_style | py::array::forcecast>::ensure(anchored);
          if (!a || a.ndim() != 1 || a.shape(0) != rest.rows())
            throw py::value_error("anchored: expected " + std::to_string(rest.rows()) + " flags (one per vertex)");
          held.assign(a.data(), a.data() + a.shape(0));
        }
        MeshCheckOptions o;
        o.near_degenerate_quality = near_degenerate_quality;
        o.duplicate_distance = duplicate_distance;
        o.far_distance = far_distance;
        o.max_listed = max_listed;
        const MeshCheckSummary s = without_gil([&] { return diagnose_mesh(rest, elements, held, o); });
        return check_dict(s);
      },
      py::arg("V"), py::arg("E"), py::arg("anchored") = py::none(), py::kw_only(),
      py::arg("near_degenerate_quality") = MeshCheckOptions{}.near_degenerate_quality,
      py::arg("duplicate_distance") = MeshCheckOptions{}.duplicate_distance,
      py::arg("far_distance") = MeshCheckOptions{}.far_distance,
      py::arg("max_listed") = MeshCheckOptions{}.max_listed,
      "diagnose_mesh(V, E, anchored=None, *, near_degenerate_quality=1e-3, duplicate_distance=1e-10,\n"
      "              far_distance=1.0, max_listed=10) -> dict\n\n"
      "The mesh pre-flight of `qpr check` (mesh/mesh_check.h): V (n, 3), E (m, 3) triangles or (m, 4)\n"
      "tets, anchored (n,) flags of the vertices handles hold (None: anchoring not checked). Returns\n"
      "status ('clean', 'warnings', 'errors'), sizes, scale and findings: dicts with defect, severity,\n"
      "count, item, first (the first offenders) and message. Defects are findings, never exceptions.");
  m.def(
      "anchored_vertices",
      [](const Scenario& sc) {
        const std::vector<char> a = anchored_vertices(sc);
        py::array_t<bool> out(static_cast<py::ssize_t>(a.size()));
        std::copy(a.begin(), a.end(), out.mutable_data());
        return out;
      },
      py::arg("scenario"),
      "anchored_vertices(scenario) -> (n,) bool\n\nThe vertices the scenario's handles and fixed patches hold.");
}

void bind_references(py::module_& m) {
  py::enum_<ReferenceEnergy>(m, "ReferenceEnergy", "What a full-space reference minimises (reference.h).")
      .value("ClassicArap", ReferenceEnergy::ClassicArap, "One rotation per element (Eq. 6).")
      .value("ModifiedArap", ReferenceEnergy::ModifiedArap, "E′ (Eq. 8–10) over the model's clusters.");
  py::class_<ReferenceOptions> options(m, "ReferenceOptions", "Options of the references; keyword construction.");
  Fields(options, "ReferenceOptions")
      .rw("energy", &ReferenceOptions::energy, "ReferenceEnergy.ClassicArap (default) or ModifiedArap.")
      .rw("parameters", &ReferenceOptions::parameters, "EnergyParameters of E′.")
      .rw("frame", &ReferenceOptions::frame, "(3, 3): minimise E′ in the frame rotated by frameᵀ.")
      .rw("max_iterations", &ReferenceOptions::max_iterations, "Iteration limit. Default 20000.")
      .rw("step_tolerance", &ReferenceOptions::step_tolerance, "Local-global step tolerance. Default 1e-10.")
      .rw("energy_tolerance", &ReferenceOptions::energy_tolerance, "Local-global energy tolerance. Default 1e-13.")
      .rw("cluster_fit", &ReferenceOptions::cluster_fit, "Rotation step with ModifiedArap. Default Exact.")
      .rw("threads", &ReferenceOptions::threads, "Ceres threads. Default 1.")
      .repr()
      .keyword_init<ReferenceOptions>();
  def_validate<decltype(options), ReferenceOptions>(options);
  py::class_<ReferenceSummary, Outcome> summary(m, "ReferenceSummary", "Result of a reference solve.");
  Fields(summary, "ReferenceSummary")
      .listed("status")
      .listed("message")
      .ro("energy_kind", &ReferenceSummary::energy_kind, "")
      .ro("converged", &ReferenceSummary::converged, "A convergence test held.")
      .ro("iterations", &ReferenceSummary::iterations, "")
      .ro("initial_energy", &ReferenceSummary::initial_energy, "")
      .ro("energy", &ReferenceSummary::energy, "arap_energy (classic) or E′ (modified) of the result.")
      .ro("handle_residual", &ReferenceSummary::handle_residual, "Largest constraint violation.")
      .ro("last_step", &ReferenceSummary::last_step, "")
      .ro("setup_seconds", &ReferenceSummary::setup_seconds, "")
      .ro("solve_seconds", &ReferenceSummary::solve_seconds, "")
      .repr();
  const auto solve = [](auto solver) {
    return [solver](const DeformableMesh& model, const Handles& handles, const HandleTargets& targets,
                    py::handle options, py::handle initial) {
      const auto opts = options_arg<ReferenceOptions>("options", options);
      Vertices init;
      if (!initial.is_none()) {
        init = matrix_view<double>("initial", initial, {model.V.rows(), "n"}, {3, "3"}, false);
      }
      ReferenceSolution solution;
      ReferenceSummary summary;
      {
        py::gil_scoped_release release;
        summary = solver(model, handles, targets, opts, &solution, init);
      }
      raise_if_unusable(summary, py::cast(summary));
      return py::make_tuple(solution.V, summary);
    };
  };
  m.def("solve_local_global", solve(&solve_local_global), py::arg("model"), py::arg("handles"), py::arg("targets"),
        py::arg("options") = py::none(), py::arg("initial") = py::none(),
        "solve_local_global(model, handles, targets, options=None, initial=None) -> (V′ (n, 3), ReferenceSummary)\n\n"
        "Full-space Sorkine–Alexa local-global ARAP with the deformer's constraints (hard), from the rest\n"
        "pose or initial (n, 3). Raises NumericalError when the solve fails (e.g. a singular global step).\n"
        "Releases the GIL.");
  m.def("solve_ceres_reference", solve(&solve_ceres_reference), py::arg("model"), py::arg("handles"),
        py::arg("targets"), py::arg("options") = py::none(), py::arg("initial") = py::none(),
        "solve_ceres_reference(model, handles, targets, options=None, initial=None) -> (V′, ReferenceSummary)\n\n"
        "Ceres on all unknowns (single-vertex handles and prescribed patches only). RuntimeError when\n"
        "qpreduce was built without Ceres (has_ceres_reference()).");
  m.def("has_ceres_reference", &has_ceres_reference, "Whether solve_ceres_reference is available.");
  m.def(
      "arap_energy",
      [](const DeformableMesh& model, py::handle deformed) {
        const Vertices Vp = matrix_view<double>("deformed", deformed, {model.V.rows(), "n"}, {3, "3"}, false);
        py::gil_scoped_release release;
        const RotationElements elements =
            model.is_tet() ? tet_elements(model.V, model.T) : spokes_and_rims_elements(model.V, model.F);
        return arap_energy(model.V, elements, Vp);
      },
      py::arg("model"), py::arg("deformed"),
      "arap_energy(model, deformed) -> float\n\n"
      "Classic ARAP energy (Eq. 6) of deformed (n, 3) against the model's rest pose.");
}

}  // namespace

void bind_deform_io(py::module_& m) {
  auto deform = m.def_submodule("deform", "Reduced ARAP mesh deformation (the deform plugin).");
  py::register_exception<IoError>(deform, "IoError", PyExc_OSError);
  bind_deformer(deform);
  bind_mesh_io(deform);
  bind_scenarios(deform);
  bind_mesh_check(deform);
  bind_references(deform);
  bind_refiner(deform);
  bind_arap(deform);
  bind_pipeline(deform);
}

}  // namespace qpreduce::python
