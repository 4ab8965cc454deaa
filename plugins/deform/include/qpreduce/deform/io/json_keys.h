// qpreduce::deform — one check JSON readers share: no object may name a key
// twice. JSON parsers keep the last value of a repeated key without a word,
// so a scene or a manifest with two "mesh" or "b" entries would silently
// lose one; the readers call this before they parse.
#pragma once

#include "qpreduce/deform/io/io_error.h"

#include <string>
#include <string_view>

namespace qpreduce::deform {

// Throws IoError "<file>: <pointer>: duplicate key '<key>'" for the first
// object that repeats a key (<pointer> is a JSON pointer such as
// "/demands/1"; "/" for the top level). Syntax errors are left to the
// parser that follows (this returns without throwing on them).
void check_unique_json_keys(std::string_view text, const std::string& file);

}  // namespace qpreduce::deform
