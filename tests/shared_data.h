// Where the tests find the shared test data (../shared/data beside the
// checkout: the Botsch–Sorkine suite, the paper's models, the references).
// $QPREDUCE_SHARED_DATA, when set, names the data folder instead; a folder
// that does not exist hides the data, as on a user's fresh clone (.ci/run
// runs the Release suite a second time that way). Tests that need the data
// skip with a message when it is absent.
#pragma once

#include <cstdlib>
#include <filesystem>
#include <string>

namespace qpreduce_test {

// The data folder this run uses, whether or not it exists.
inline std::string shared_data_location() {
  if (const char* env = std::getenv("QPREDUCE_SHARED_DATA")) return env;
  return (std::filesystem::path(QPREDUCE_SHARED_DIR) / "data").lexically_normal().string();
}

// The data folder, or "" when it is absent (the data tests then skip).
inline std::string shared_data() {
  const std::string dir = shared_data_location();
  std::error_code ec;
  return std::filesystem::is_directory(dir, ec) ? dir : std::string();
}

}  // namespace qpreduce_test

// Declares `dir` (the data folder) or skips the test case with a message.
#define REQUIRE_SHARED_DATA(dir)                                                                       \
  const std::string dir = qpreduce_test::shared_data();                                                \
  if (dir.empty()) {                                                                                   \
    WARN("skipped: the shared test data is not at " << qpreduce_test::shared_data_location()           \
                                                    << " (set QPREDUCE_SHARED_DATA to its folder)"); \
    return;                                                                                            \
  }
