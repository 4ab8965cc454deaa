#include "deform_run.h"
#include "path_roles.h"
#include "refine_run.h"
#include "run_files.h"

#include "reports.h"
#include "preflight.h"
#include "validators.h"

#include <qpreduce/deform/mesh/geometry.h>
#include <qpreduce/deform/io/file_kind.h>
#include <qpreduce/deform/io/mesh_io.h>
#include <qpreduce/deform/io/tet_io.h>
#include <qpreduce/deform/pipeline/run_scenario.h>
#include <qpreduce/util/cpu_features.h>
#include <qpreduce/util/timer.h>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <numeric>
#include <cstdio>
#include <fstream>
#include <stdexcept>

namespace qpr {

using namespace qpreduce;
using namespace qpreduce::deform;

double peak_rss_mb() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return static_cast<double>(usage.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

namespace {

std::string frame_path(const std::string& pattern, int frame, bool many) {
  const auto pos = pattern.find("{frame}");
  if (pos != std::string::npos) {
    std::string s = pattern;
    s.replace(pos, 7, fmt::format("{:03d}", frame));
    return s;
  }
  if (!many) return pattern;
  const auto dot = pattern.find_last_of('.');
  return dot == std::string::npos ? fmt::format("{}_{:03d}", pattern, frame)
                                  : fmt::format("{}_{:03d}{}", pattern.substr(0, dot), frame, pattern.substr(dot));
}

// .mesh, .node, .ele in any case, as the plugin's readers dispatch.
bool is_tet_path(const std::string& path) { return mesh_file_kind(path) == MeshFileKind::Tets; }

}  // namespace

void write_pose(const std::string& path, const Vertices& V, const TriangleMesh* surface, const TetMesh* solid) {
  if (surface) {
    write_triangle_mesh(path, TriangleMesh{V, surface->F});
    return;
  }
  if (is_tet_path(path)) {
    write_tet_mesh(path, TetMesh{V, solid->T, solid->F});
  } else if (solid->F.rows() > 0) {
    write_triangle_mesh(path, TriangleMesh{V, solid->F});  // the boundary surface
  } else {
    throw std::invalid_argument(path + ": this tet mesh has no boundary triangles; write a .mesh instead");
  }
}

void add_scenario_options(CLI::App* cmd, ScenarioArgs* a) {
  add_path_option(cmd, PathRole::Input, "mesh", a->mesh, "Mesh: .obj .off .ply (surface) or .mesh .node/.ele (tets)");
  auto* sel = add_path_option(cmd, PathRole::Input, "--sel", a->sel, "Botsch–Sorkine selection (0 fixed, 1 free, 2 handle)")->check(CLI::ExistingFile);
  add_path_option(cmd, PathRole::Input, "--def", a->def, "Botsch–Sorkine 4×4 handle transform")->check(CLI::ExistingFile)->needs(sel);
  add_path_option(cmd, PathRole::Input, "--anim", a->anim, "Recorded handle poses (.anim)")->check(CLI::ExistingFile);
  add_path_option(cmd, PathRole::Scene, "--scene", a->scene, "JSON scene (mesh, handles, patches, proxies, parameters)")->check(CLI::ExistingFile);
  cmd->add_option("--frames", a->frames, "With --sel/--def: frames from rest to the .def pose")
      ->check(whole_number_between(1, 100000));
  auto* lp =
      cmd->add_option("--linear-proxies", a->linear_proxies, "Linear proxies (farthest-point samples), default 33")
          ->check(whole_number_between(1, 10000000));
  auto* lg = add_path_option(cmd, PathRole::Input, "--linear-groups", a->linear_groups, "Linear proxies as vertex groups (.id)")->check(CLI::ExistingFile)->excludes(lp);
  cmd->add_flag("--exact-handles", a->exact_handles,
                "Make every point-handle vertex its own linear proxy at precompute, so the subspace meets its "
                "targets exactly (--linear-proxies more samples around them; precompute grows with their count)")
      ->excludes(lg);
  auto* rp = cmd->add_option("--rotational-proxies", a->rotational_proxies,
                             "Rotational clusters (spectral k-means), default 27")
                 ->check(whole_number_between(1, 10000000));
  add_path_option(cmd, PathRole::Input, "--rotational-clusters", a->rotational_clusters, "Rotational clusters (.id)")->check(CLI::ExistingFile)->excludes(rp);
  add_path_option(cmd, PathRole::Input, "--affine-patches", a->affine_patches, "Affine patches (.id: 0 free, k > 0 patch k)")->check(CLI::ExistingFile);
  const DeformerOptions defaults;
  cmd->add_option("--iterations", a->iterations,
                  fmt::format("Phase 1/Phase 2 rounds per frame: the cap with --tolerance and --time-budget-ms "
                              "(default {})",
                              defaults.iterations))
      ->check(whole_number_between(1, 100000));
  cmd->add_option("--tolerance", a->tolerance,
                  fmt::format("Stop a frame's rounds once the relative fixed-point residual |ΔS|/|S| is at most this "
                              "(default {:g}; 0: always --iterations rounds unless the budget ends them)",
                              defaults.tolerance))
      ->check(number_between(0.0, 1.0));
  cmd->add_option("--time-budget-ms", a->time_budget_ms,
                  fmt::format("Stop a frame's rounds once they have run this many milliseconds (default {:g}; 0: "
                              "no budget; the first frame's cold start has none)",
                              1e3 * defaults.time_budget))
      ->check(number_between(0.0, 1e6));
  cmd->add_option("--cold-start-rounds", a->cold_start_rounds,
                  "The first frame after the handles are set runs to a fixed-point residual of 1e-6 within this "
                  "many rounds (default 500; 0: like the other frames)")
      ->check(whole_number_between(0, 100000));
  cmd->add_option("--rotation-step", a->rotation_step,
                  "Phase 2 rotation fit: exact (the cluster's covariance with the Q-corrections: block-coordinate "
                  "descent on E') or paper (Eq. 19, Q dropped)")
      ->check(CLI::IsMember({"exact", "paper"}));
  cmd->add_option("--anderson", a->anderson_window,
                  "Anderson acceleration of the rounds with this window (1-16; energy safeguard; needs "
                  "--rotation-step exact), 0: off; default 5 with exact, 0 with paper")
      ->check(whole_number_between(0, 16));
  cmd->add_flag("--no-second-order", a->no_second_order,
                "Rounds even on stiff point-handle sets (default: Newton steps on the rotations there)");
  cmd->add_flag("--exact-unreachable", a->exact_unreachable,
                "Keep the exact (least-squares) form of point-handle sets the subspace cannot meet reliably "
                "(default: soft constraints, with a warning; see docs/robustness.md)");
  cmd->add_flag("--double-basis", a->double_basis,
                "Keep the reconstruction basis in double (twice its memory, cache and bytes per frame): poses to "
                "double round-off instead of float's (docs/robustness.md, \"Units\")");
  cmd->add_option("--alpha", a->alpha, "Penalty α on the linearised rotations (Eq. 10)")
      ->check(number_between(0, kMaxPenalty));
  cmd->add_option("--beta", a->beta, "Normal penalty β (surfaces, Eq. 10)")->check(number_between(0, kMaxPenalty));
  cmd->add_option("--gamma", a->gamma, "Moving-frame penalty γ between neighbouring elements (Eq. 11), default 0")
      ->check(number_between(0, kMaxPenalty));
  cmd->add_option("--model", a->model, "Deformation model: arap (rotations) or conformal (scaled rotations, Eq. 48–49)")
      ->check(CLI::IsMember({"arap", "conformal"}));
  cmd->add_option("--psi", a->psi, "Conformal model: scales within [1/ψ, ψ], default 2")->check(number_above(1.0, 1e6));
  cmd->add_option("--soft", a->soft, "Soft handle constraints with weight δ (Eq. 18) instead of hard ones")
      ->check(number_above(0));
}

namespace {

// The mesh, the model and the handles of a JSON scene.
void read_scene_inputs(const std::string& path, LoadedScenario* ls) {
  const Scene scene = read_scene(path);
  ls->tet = scene.is_tet;
  ls->surface = scene.surface;
  ls->solid = scene.solid;
  ls->scenario = scenario_from_scene(scene);
}

// The mesh file and its handles from --sel/--def or --anim.
void read_mesh_inputs(const ScenarioArgs& a, LoadedScenario* ls) {
  if (a.mesh.empty()) throw std::invalid_argument("MESH is required with --sel/--def and --anim");
  const bool tet = ls->tet = is_tet_path(a.mesh);
  if (tet) ls->solid = read_tet_mesh(a.mesh); else ls->surface = read_triangle_mesh(a.mesh);
  const Vertices& V = tet ? ls->solid.V : ls->surface.V;
  Scenario& sc = ls->scenario;
  if (!a.sel.empty()) {
    Selection sel = read_sel(a.sel);
    if (tet && sel.size() < V.rows()) {
      // Botsch–Sorkine selections of the surface apply to a tet mesh whose
      // first nodes are that surface (tetgen -Y); interior nodes are free.
      std::fprintf(stderr, "  note: %s has %ld entries for %ld nodes; the remaining nodes are free\n",
                   a.sel.c_str(), static_cast<long>(sel.size()), static_cast<long>(V.rows()));
      sel.roles.resize(static_cast<size_t>(V.rows()), SelRole::Free);
    }
    sc = scenario_from_sel_def(V, sel, read_def(a.def), a.frames);
  } else {
    sc = scenario_from_anim(V, read_anim(a.anim));
  }
  if (tet) sc.model.T = ls->solid.T; else sc.model.F = ls->surface.F;
}

// Adds the groups of an --affine-patches file as Affine patches after those
// the handles made; a vertex already in a patch is an error.
void add_affine_patches(const VertexGroups& g, const std::string& file, DeformableMesh* model) {
  const Index n = model->V.rows();
  if (model->patch_of_vertex.empty()) model->patch_of_vertex.assign(static_cast<size_t>(n), -1);
  for (const auto& members : g.members) {
    const int id = static_cast<int>(model->patch_types.size());
    for (int v : members) {
      if (model->patch_of_vertex[v] >= 0) {
        throw std::invalid_argument(fmt::format("{}: vertex {} is already in patch {} (from the handles)",
                                                file, v, model->patch_of_vertex[v]));
      }
      model->patch_of_vertex[v] = id;
    }
    model->patch_types.push_back(PatchType::Affine);
  }
}

// The deformer options the arguments ask for (the scene's own are applied
// later, by apply_scenario_options).
DeformerOptions deformer_options(const ScenarioArgs& a, const std::optional<ModelKind>& scenario_model, bool tet) {
  DeformerOptions options;
  if (a.linear_proxies > 0) options.linear_proxies = a.linear_proxies;
  if (a.rotational_proxies > 0) options.rotational_proxies = a.rotational_proxies;
  if (a.iterations) options.iterations = *a.iterations;
  if (a.tolerance) options.tolerance = *a.tolerance;
  if (a.time_budget_ms) options.time_budget = 1e-3 * *a.time_budget_ms;
  if (a.cold_start_rounds) options.cold_start_rounds = *a.cold_start_rounds;
  options.rotation_fit = a.rotation_step == "paper" ? ClusterRotationFit::PaperPhase2 : ClusterRotationFit::Exact;
  if (a.anderson_window) {
    if (*a.anderson_window > 0 && options.rotation_fit != ClusterRotationFit::Exact)
      throw std::invalid_argument("--anderson " + std::to_string(*a.anderson_window) +
                                  " needs --rotation-step exact (the safeguard's energy is E' at the exact step)");
    options.anderson_window = *a.anderson_window;
  } else if (options.rotation_fit != ClusterRotationFit::Exact) {
    options.anderson_window = 0;  // the paper's step runs plain rounds
  }
  options.second_order = !a.no_second_order;
  options.soften_unreachable_handles = !a.exact_unreachable;
  options.double_basis = a.double_basis;
  if (a.alpha) options.energy.alpha = *a.alpha;
  if (a.beta) options.energy.beta = *a.beta;
  if (a.gamma) options.energy.gamma = *a.gamma;
  if (!a.model.empty()) options.model = a.model == "conformal" ? ModelKind::Conformal : ModelKind::Arap;
  if (a.psi) {
    if (options.model != ModelKind::Conformal && scenario_model != ModelKind::Conformal) {
      throw std::invalid_argument("--psi applies to the conformal model (--model conformal)");
    }
    options.conformal_bound = *a.psi;
  }
  if (tet) options.energy.beta = 0.0;
  return options;
}

}  // namespace

LoadedScenario load_scenario(const ScenarioArgs& a, bool strict) {
  const int sources = !a.sel.empty() + !a.anim.empty() + !a.scene.empty();
  if (sources != 1) throw std::invalid_argument("give exactly one of --sel/--def, --anim, --scene");
  if (!a.sel.empty() && a.def.empty()) throw std::invalid_argument("--sel needs --def");

  LoadedScenario ls;
  bool& tet = ls.tet;
  Scenario& sc = ls.scenario;
  if (!a.scene.empty()) read_scene_inputs(a.scene, &ls); else read_mesh_inputs(a, &ls);
  const Index n = sc.model.V.rows();
  if (!a.linear_groups.empty()) {
    const VertexIds ids = read_id(a.linear_groups);
    ids.validate(n);
    (void)linear_groups_from_ids(ids);  // the format's rule: linear-group ids are >= 0
    sc.model.linear = linear_proxies_from_ids(ids.ids, n);
  }
  if (!a.rotational_clusters.empty()) {
    const VertexIds ids = read_id(a.rotational_clusters);
    ids.validate(n);
    const VertexGroups g = rotation_groups_from_ids(ids);
    sc.model.clusters = tet ? element_clusters_from_vertex_labels(g.group_of, sc.model.T) : g.group_of;
  }
  if (!a.affine_patches.empty()) {
    const VertexIds ids = read_id(a.affine_patches);
    ids.validate(n);
    add_affine_patches(affine_patches_from_ids(ids), a.affine_patches, &sc.model);
  }
  if (a.soft) {
    sc.constraints.soft = true;
    sc.constraints.delta = *a.soft;
  }
  ls.name = !a.scene.empty() ? a.scene : a.mesh;
  ls.options = deformer_options(a, ls.scenario.model_kind, tet);
  if (a.exact_handles && !sc.handles.points.empty()) {
    if (sc.model.linear.count() > 0) {
      throw std::invalid_argument("--exact-handles makes the linear proxies; the scene gives its own (proxies/linear)");
    }
    DeformerOptions counts = ls.options;  // the scene's proxy count, when it gives one
    apply_scenario_options(sc, &counts);
    sc.model.linear = exact_handle_proxies(sc.model, sc.handles, counts.linear_proxies);
  }
  ls.preflight = preflight(ls.scenario, ls.name, strict);
  check_scenario(ls.scenario, ls.name);
  return ls;
}

namespace {

void progress_bar(const std::string& stage, double fraction) {
  const int width = 30, filled = static_cast<int>(fraction * width + 0.5);
  std::fprintf(stderr, "\r  precompute [%s%s] %3d%% %-16s", std::string(static_cast<size_t>(filled), '#').c_str(),
               std::string(static_cast<size_t>(width - filled), ' ').c_str(), static_cast<int>(100 * fraction),
               stage.c_str());
  if (fraction >= 1.0) std::fprintf(stderr, "\n");
  std::fflush(stderr);
}

// What the frames of a run measured, and the last pose.
struct FrameSeries {
  std::vector<double> iter_us, recon_ms, frame_ms, residual;  // one per frame; residual / bbox diagonal
  std::vector<int> rounds;                                     // rounds run, one per frame
  std::vector<std::string> stops;                              // what ended them, one per frame
  std::vector<double> fixed_point_residual;                    // ‖ΔS‖/‖S‖ after them, one per frame
  FrameSummary last;                                           // the last frame's summary
};

FrameSeries frame_series(const ScenarioRunSummary& run) {
  FrameSeries s;
  for (const FrameSummary& fs : run.frames) {
    s.iter_us.push_back(1e6 * fs.solve_seconds / std::max(1, fs.iterations));
    s.recon_ms.push_back(1e3 * fs.reconstruct_seconds);
    s.frame_ms.push_back(1e3 * fs.total_seconds);
    s.rounds.push_back(fs.iterations);
    s.stops.emplace_back(to_string(fs.stop));
    s.fixed_point_residual.push_back(fs.fixed_point_residual);
    s.last = fs;
  }
  s.residual = run.handle_residual;
  return s;
}

// Whether frame f (of `frames`) is one the settings write.
bool writes_frame(const RunSettings& settings, int f, int frames) {
  const std::vector<int>& wf = settings.write_frames;
  return !settings.out_path.empty() &&
         (std::find(wf.begin(), wf.end(), f) != wf.end() ||
          (f == frames - 1 && std::find(wf.begin(), wf.end(), -1) != wf.end()));
}

// The report's "settle" object.
nlohmann::json settle_json(const FrameSummary& settle, double tolerance) {
  return {{"rounds", settle.iterations},
          {"fixed_point_residual", settle.fixed_point_residual},
          {"seconds", settle.total_seconds},
          {"status", to_string(settle.status)},
          {"tolerance", tolerance}};
}

// What the deformer was built from and with: sizes, options, model, clusters.
void report_model(const Deformer& deformer, const Scenario& scenario, const DeformerOptions& options,
                  const PrecomputeSummary& pre, nlohmann::json& report) {
  report["vertices"] = pre.vertices;
  report["elements"] = pre.elements;
  report["mesh_type"] = scenario.model.is_tet() ? "tet" : "triangle";
  report["linear_proxies"] = pre.linear_proxies;
  report["rotational_proxies"] = pre.rotational_proxies;
  report["patches"] = pre.patches;
  report["reduced_size"] = pre.reduced_size;
  report["frames"] = static_cast<int>(scenario.frames.size());
  report["iterations"] = options.iterations;
  report["tolerance"] = options.tolerance;
  report["time_budget_ms"] = 1e3 * options.time_budget;
  report["rotation_step"] = to_string(options.rotation_fit);
  report["anderson_window"] = options.anderson_window;
  report["second_order"] = options.second_order;
  report["soften_unreachable_handles"] = options.soften_unreachable_handles;
  report["double_basis"] = options.double_basis;
  report["alpha"] = options.energy.alpha;
  report["beta"] = options.energy.beta;
  report["gamma"] = options.energy.gamma;
  report["model"] = deformer.model() ? deformer.model()->name() : "";
  // Σ_{a<b} W_ab‖s_a − s_b‖²_F over neighbouring clusters (what γ, Eq. 11, penalises).
  report["cluster_rotation_roughness"] = cluster_rotation_roughness(
      cluster_geometry(scenario.model.V, deformer.elements(), deformer.clusters(), deformer.rotational_proxies()),
      deformer.rotations());
  if (options.model == ModelKind::Conformal) {
    report["psi_bound"] = options.conformal_bound;
    const Eigen::VectorXd psi = deformer.cluster_scales();
    report["psi_min"] = psi.minCoeff();
    report["psi_max"] = psi.maxCoeff();
  }
}

// The timing table of a run (stdout).
void print_table(const std::string& name, const Scenario& scenario, const PrecomputeSummary& pre,
                 const RunSettings& settings, bool cache_loaded, const nlohmann::json& report, int iterations,
                 const FrameSeries& s) {
  const double peak_mb = report["precompute_peak_mb"].get<double>(), op_ms = report["op_ms"].get<double>();
  fmt::print("{}: {} vertices, {} {} elements, {} linear / {} rotational proxies, {} patches\n", name,
             pre.vertices, pre.elements, scenario.model.is_tet() ? "tet" : "rotation", pre.linear_proxies,
             pre.rotational_proxies, pre.patches);
  if (cache_loaded) {
    fmt::print("  {:<28}{:>12.3f} s   (loaded from {}, peak RSS {:.0f} MB)\n", "precompute", pre.total_seconds,
               settings.run.cache_path, peak_mb);
  } else {
    fmt::print("  {:<28}{:>12.3f} s   (peak RSS {:.0f} MB, backend {})\n", "precompute", pre.total_seconds, peak_mb,
               to_string(pre.subspace.backend_used));
  }
  fmt::print("  {:<28}{:>12.3f} ms\n", "OP (set handles)", op_ms);
  const auto [fewest, most] = std::minmax_element(s.rounds.begin(), s.rounds.end());
  fmt::print("  {:<28}{:>12.2f} µs   (median over {} frames, {} rounds each{})\n", "one iteration", median(s.iter_us),
             s.frame_ms.size(), *fewest == *most ? std::to_string(*fewest) : fmt::format("{}-{}", *fewest, *most),
             *fewest == *most && *most == iterations ? "" : fmt::format(", cap {}", iterations));
  fmt::print("  {:<28}{:>12.3f} ms\n", "reconstruction", median(s.recon_ms));
  fmt::print("  {:<28}{:>12.3f} ms\n", "frame total", median(s.frame_ms));
  fmt::print("  {:<28}{:>12.2e}      (max over frames, / bbox diagonal)\n", "handle residual", report["handle_residual_max"].get<double>());
  fmt::print("  {:<28}{:>12.5g}      (last frame)\n", "ARAP energy", report["arap_energy"].get<double>());
  const auto budget_stops = std::count(s.stops.begin(), s.stops.end(), to_string(RoundStop::TimeBudget));
  fmt::print("  {:<28}{:>12.2e}      (last frame, {} rounds, ended by the {}; |ΔS|/|S|){}\n", "fixed-point residual",
             s.last.fixed_point_residual, s.last.iterations, to_string(s.last.stop),
             budget_stops > 0 ? fmt::format("; {} of {} frames ended by the time budget", budget_stops, s.stops.size())
                              : std::string());
}

// The report's precompute keys.
void report_precompute(const PrecomputeSummary& pre, bool cache_loaded, double peak_mb, nlohmann::json& report) {
  report["precompute_s"] = pre.total_seconds;
  report["precompute_from_cache"] = cache_loaded;
  report["precompute_breakdown_s"] = {{"clustering", pre.clustering_seconds},
                                      {"assembly", pre.assembly_seconds},
                                      {"subspace", pre.subspace_seconds},
                                      {"reduction", pre.reduction_seconds}};
  report["precompute_peak_mb"] = peak_mb;
  report["subspace_backend"] = to_string(pre.subspace.backend_used);
  report["kkt_residual"] = pre.subspace.kkt_residual;
  report["blas_core"] = qpreduce::blas_core();  // the BLAS kernels behind it and OP (cpu_features.h)
}

// The report's per-frame keys: timings (medians), residuals, rounds, stops.
void report_frames(const FrameSeries& s, nlohmann::json& report) {
  report["iteration_us"] = median(s.iter_us);
  report["reconstruction_ms"] = median(s.recon_ms);
  report["frame_ms"] = median(s.frame_ms);
  report["handle_residual_max"] = *std::max_element(s.residual.begin(), s.residual.end());
  // How far the last pose is from the alternation's fixed point, and the rounds it took.
  report["fixed_point_residual"] = s.last.fixed_point_residual;
  report["rounds"] = s.last.iterations;
  report["rounds_total"] = std::accumulate(s.rounds.begin(), s.rounds.end(), 0);
  report["rounds_per_frame"] = s.rounds;
  report["stop"] = to_string(s.last.stop);  // what ended the last frame's rounds
  report["stop_per_frame"] = s.stops;
  report["fixed_point_residual_per_frame"] = s.fixed_point_residual;
  report["second_order_steps"] = s.last.second_order;  // the last frame took Newton steps, not rounds
  if (std::isfinite(s.last.model_energy)) {
    report["model_energy"] = s.last.model_energy;
    report["rejected_steps"] = s.last.rejected_steps;
  }
}

}  // namespace

nlohmann::json run_scenario(const Scenario& scenario, const TriangleMesh* surface, const TetMesh* solid,
                            const RunSettings& settings, RunOutputs* outputs) {
  check_outputs(settings);
  const ScenarioRunOptions& run_options = settings.run;
  const int frames = static_cast<int>(scenario.frames.size());
  double peak_mb = 0.0;
  ScenarioRunHooks hooks;
  if (settings.progress && isatty(fileno(stderr)) != 0) hooks.progress = progress_bar;
  hooks.prepared = [&](const Deformer& deformer, bool from_cache) {
    peak_mb = peak_rss_mb();
    if (!from_cache && !run_options.cache_path.empty()) deformer.save(run_files().stage(run_options.cache_path));
  };
  Deformer deformer;
  hooks.frame = [&](int f, const Vertices& pose) {
    if (outputs && f == frames - 1) {  // the deformer's state after the last frame, before any settle
      outputs->clusters = deformer.clusters();
      outputs->rotations = deformer.rotations();
      outputs->global_rotation = deformer.global_rotation();
    }
    if (writes_frame(settings, f, frames))
      write_pose(run_files().stage(frame_path(settings.out_path, f, settings.write_frames.size() > 1)), pose, surface,
                 solid);
  };
  ScenarioPoses poses;
  const ScenarioRunSummary run = run_scenario(scenario, run_options, &deformer, &poses, hooks);
  const DeformerOptions& options = run.options;  // with the scenario's overrides
  if (!run.cache_message.empty()) std::fprintf(stderr, "  cache not used: %s\n", run.cache_message.c_str());
  if (run.handles.status != Status::Success && usable(run.handles.status) && !run_options.strict) {
    std::fprintf(stderr, "  warning: %s%s\n", run.handles.message.c_str(),
                 run.handles.beyond_subspace
                     ? " (name the point-handle vertices at precompute to meet them exactly: --exact-handles)"
                     : "");
  }
  if (!run.ok()) throw std::runtime_error(run.message);
  const FrameSeries s = frame_series(run);
  if (run.handles.status != Status::Success && !s.residual.empty()) {
    std::fprintf(stderr, "  warning: the handles end up to %.2e of the bounding-box diagonal from their targets\n",
                 *std::max_element(s.residual.begin(), s.residual.end()));
  }
  if (run.refined && writes_frame(settings, frames - 1, frames))  // the refined pose replaces the reduced one
    write_pose(run_files().stage(frame_path(settings.out_path, frames - 1, settings.write_frames.size() > 1)),
               poses.refined, surface, solid);
  if (outputs) {
    outputs->options = options;
    outputs->last = poses.last;
    outputs->settled = poses.settled;
  }

  const PrecomputeSummary& pre = run.precompute;
  nlohmann::json report;
  report["name"] = settings.name;
  report_model(deformer, scenario, options, pre, report);
  report_precompute(pre, run.from_cache, peak_mb, report);
  report["op_ms"] = 1e3 * run.op_seconds;
  report["op_status"] = to_string(run.handles.status);
  report_frames(s, report);
  report["arap_energy"] = run.arap_energy;
  report["bounding_box_diagonal"] = run.diagonal;
  if (run.settled) report["settle"] = settle_json(run.settle, run_options.settle_tolerance);
  if (run.refined) report["refine"] = refine_json(run.refine, *run_options.refine);
  if (!settings.preflight.is_null()) report["preflight"] = settings.preflight;
  report["run"] = to_json(run.report());  // every stage's summary (docs/formats.md, "Summaries")

  print_table(settings.name, scenario, pre, settings, run.from_cache, report, options.iterations, s);
  if (run.settled)
    fmt::print("  {:<28}{:>12.3f} ms   ({} rounds to the fixed point at the last frame's targets, residual {:.2e})\n",
               "settle (reduced)", 1e3 * run.settle.total_seconds, run.settle.iterations,
               run.settle.fixed_point_residual);
  if (run.refined) print_refine_line(report["refine"]);
  if (!settings.report_path.empty()) write_json(run_files().stage(settings.report_path), report);
  return report;
}

}  // namespace qpr
