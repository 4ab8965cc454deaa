// qpreduce::deform — whether a file is a deformer cache (Deformer::save,
// Deformer::load), told by its header alone.
#pragma once

#include <string>

namespace qpreduce::deform {

// True when `path` names a regular file that starts with a deformer cache's
// magic bytes (it may still be truncated or of another version: load checks
// that). False when it does not exist, cannot be read, or holds anything else.
bool is_deformer_cache(const std::string& path);

// True when Deformer::save may write `path`: it does not exist, is empty,
// is not a regular file (/dev/null), or is a deformer cache
// (is_deformer_cache). Writers refuse any other file so that a slip
// (`--cache mesh.off`) never replaces an input.
bool may_replace_with_cache(const std::string& path);

}  // namespace qpreduce::deform
