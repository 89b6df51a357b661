#!/bin/sh
# Removes a test's output folder once the tests that read it ran (a run's checkpoints take a
# gigabyte); GEO_KEEP_TEST_DIRS=1 keeps it for inspection.
#   remove_folder.sh FOLDER
set -eu
[ "${GEO_KEEP_TEST_DIRS:-}" = 1 ] || rm -rf "$1"
