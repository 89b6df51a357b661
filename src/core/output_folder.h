// A tool's output folder holding files of the user's too: the tool records what it writes there
// (a manifest), so that replacing its earlier outputs never touches anything else.
#pragma once

#include <string>
#include <vector>

namespace geo {

// Prepares `folder` (created when missing) for a run that will write the files `planned` (plain
// names inside it) and records them in its manifest (`manifest`, a text file of one name per line
// in the folder) before any is written, so that a run that stops half-way still names them.
// - An empty or new folder is used as it is.
// - A folder holding anything is refused unless `force`; with `force`, the files the manifest of
//   an earlier run names are removed (only regular files directly in the folder), and nothing else.
// - A planned name that exists and was not written by the tool (no manifest names it) is refused,
//   naming the file, before anything is removed or written: the user's trajectory.txt stays.
// - `folder` that is one of `frame_folders` (after links and ../: a folder the input's frames are
//   read from, which a later run would read the outputs from as frames) is refused.
// `option` names the command-line option in messages. Returns how many earlier outputs were removed.
// Throws std::runtime_error.
int64_t prepare_output_folder(const std::string& folder, const std::string& option, const std::string& manifest,
                              const std::vector<std::string>& planned, bool force,
                              const std::vector<std::string>& frame_folders);

// The refusals of prepare_output_folder that need no list of outputs (an empty name, a frame folder,
// a file, a non-empty folder without `force`), checked without writing anything: before work that
// comes ahead of the outputs (geo_infer --refine trains first).
void check_output_folder(const std::string& folder, const std::string& option, bool force,
                         const std::vector<std::string>& frame_folders);

}  // namespace geo
