// instruction_probe: one on-site step (OP) and one frame of the deformer on
// a Table 1 model, in functions of their own, so that callgrind can count
// the instructions of each (scripts/instruction_guard.py, the CI guard;
// docs/performance.md, "Instruction guard"):
//
//     instruction_probe <Model>
//
// loads the model precomputed in $QPREDUCE_BENCH_CACHE_DIR (bench_deform's
// cache; precomputed and written there when absent), then
//   qpreduce_probe_op      Deformer::set_handles for bench_deform's OP/<Model>
//                          handles (8 farthest-point vertices, default options);
//   (the set's first frame at the handles' rest positions: its cold start,
//   not counted)
//   qpreduce_probe_frame   one default frame with the first handle moved as in
//                          Frame/<Model> (rounds and reconstruction).
// Prints what ran (sizes, status, rounds) on one line. Under valgrind:
//     valgrind --tool=callgrind --toggle-collect=qpreduce_probe_op
//         --toggle-collect=qpreduce_probe_frame build/bin/instruction_probe Cactus
// and callgrind_annotate --inclusive=yes gives each function's count. Run it
// on one thread (OMP_NUM_THREADS=1, OPENBLAS_NUM_THREADS=1) so that the
// counts do not depend on the machine's cores. Built with valgrind's
// callgrind.h, it starts callgrind's instrumentation itself after loading
// the model (its summary line says so), so that valgrind's
// --instr-atstart=no runs the load at a fraction of the instrumented cost.
#include "deform_models.h"

#include <fmt/format.h>

#if __has_include(<valgrind/callgrind.h>)
#include <valgrind/callgrind.h>
#define QPREDUCE_PROBE_CLIENT_REQUESTS 1
#endif

#include <exception>
#include <string>

using namespace qpreduce;
using namespace qpreduce::deform;

#ifdef QPREDUCE_PROBE_CLIENT_REQUESTS
constexpr bool kClientRequests = true;
#else
constexpr bool kClientRequests = false;
#endif

// Not inlined and not static: callgrind's --toggle-collect finds them by name.
extern "C" __attribute__((noinline)) void qpreduce_probe_op(Deformer* deformer, const Handles* handles,
                                                           ConstraintSummary* out) {
  *out = deformer->set_handles(*handles);
}

extern "C" __attribute__((noinline)) void qpreduce_probe_frame(Deformer* deformer, const HandleTargets* targets,
                                                              Vertices* vertices, FrameSummary* out) {
  *out = deformer->frame(*targets, vertices);
}

int main(int argc, char** argv) {
  if (argc != 2 || bench::find_model(argv[1]) == nullptr) {
    std::string names;
    for (const bench::ModelSpec& spec : bench::kModels) names += std::string(names.empty() ? "" : ", ") + spec.name;
    fmt::print(stderr, "usage: instruction_probe <Model>, one of {}\n", names);
    return 2;
  }
  const bench::ModelSpec& spec = *bench::find_model(argv[1]);
  try {
    DeformerOptions options;
    const DeformableMesh model = bench::read_model(spec, &options);
    Deformer deformer;
    const PrecomputeSummary pre =
        bench::load_or_precompute(spec, model, options, bench::cache_path(spec), &deformer);
    Vertices rest;
    const Handles handles = bench::spread_handles(model, &rest);
    const double diagonal = bounding_box_diagonal(model.V);

    ConstraintSummary cs;
#ifdef QPREDUCE_PROBE_CLIENT_REQUESTS
    CALLGRIND_START_INSTRUMENTATION;
#endif
    qpreduce_probe_op(&deformer, &handles, &cs);
    if (!cs.usable()) throw std::runtime_error("handles: " + cs.message);
    Vertices vertices;
    HandleTargets targets;
    targets.points = rest;
    const FrameSummary first = deformer.frame(targets, &vertices);
    targets = bench::moved_targets(rest, diagonal, 1);
    FrameSummary frame;
    qpreduce_probe_frame(&deformer, &targets, &vertices, &frame);
    fmt::print("{}: vertices {}, reduced {}, OP: {} (fast path {}), first frame {} rounds, frame {} rounds{}\n",
               spec.name, pre.vertices, pre.reduced_size, cs.message, cs.fast_path ? 1 : 0, first.iterations,
               frame.iterations, kClientRequests ? " (callgrind client requests)" : "");
  } catch (const std::exception& e) {
    fmt::print(stderr, "instruction_probe: {}\n", e.what());
    return 1;
  }
  return 0;
}
