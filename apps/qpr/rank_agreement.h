// qpr — the ranks of an MPI job agree on their inputs, or stop together.
//
// Every rank of `mpirun -np K qpr precompute|precompute-gmrf|qp --backend
// mumps` parses its own command line and reads its own files; ranks given
// different options or files (an MPMD line, a file that differs between
// nodes) would meet in the factorization with different matrices and crash
// or hang there. Before any work each rank fingerprints what it was given
// and the fingerprints are compared: a mismatch ends every rank with exit 2
// and one message, from rank 0, naming what differs and on which ranks.
#pragma once

#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace CLI {
class App;
}

namespace qpr {

// One fingerprint per option of `command` (in its definition order, the same
// on every rank): the values given, and for an input path (path_roles.h) the
// contents of the file (with its TetGen set, or the files a scene names:
// files_of), or of every file under the directory, instead of the path
// (nodes may keep their copies at different paths). Outputs are not
// fingerprinted (rank 0 writes them).
std::vector<std::pair<std::string, std::uint64_t>> option_fingerprints(const CLI::App& command);

// The message for fingerprints[r] of every rank r (rank 0's are the
// reference): "" when every rank matches rank 0, else what differs, e.g.
// "the ranks were not given the same inputs: --rotational-proxies differs on
// rank 1; the contents of MESH differ on ranks 1, 3 (…)".
std::string rank_mismatch(const std::vector<std::string>& names,
                          const std::vector<std::vector<std::uint64_t>>& fingerprints);

}  // namespace qpr
