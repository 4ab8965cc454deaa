#!/usr/bin/env bash
# with_shared_data.sh DEFAULT_DATA_DIR COMMAND [ARG...]
# Runs a test command that reads the shared test data (tests/shared_data.h):
# the data folder is $QPREDUCE_SHARED_DATA when set, else DEFAULT_DATA_DIR
# (../shared/data beside the checkout). When it is absent the test is
# skipped: a message and exit code 77 (CTest's SKIP_RETURN_CODE). Otherwise
# every argument's DEFAULT_DATA_DIR is replaced by the folder in use and the
# command runs.
set -u
default="$1"
shift
data="${QPREDUCE_SHARED_DATA:-$default}"
if [ ! -d "$data" ]; then
  echo "skipped: the shared test data is not at $data (set QPREDUCE_SHARED_DATA to its folder)"
  exit 77
fi
args=()
for a in "$@"; do args+=("${a//"$default"/"$data"}"); done
exec "${args[@]}"
