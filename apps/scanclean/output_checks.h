#pragma once
//! Checks every command makes before it reads a byte of input: inputs exist and are what the
//! command expects (a file, not a folder), outputs go to an existing, writable folder, have a
//! known format, and are neither an input nor another output. Messages name the option as the
//! user typed it (-o, --outliers, ...) and the path. \throw OptionError (exit 2) or IoError
//! (exit 4: missing input, missing or unwritable folder).

#include <filesystem>
#include <string>
#include <vector>

namespace scanclean::app {

//! A path and the option (or positional name) it came from, e.g. {"-o", "out.ply"}.
struct PathArg {
  std::string option;
  std::filesystem::path path;
};

//! Input files: each must exist and be a regular file (a folder is reported as a folder).
void check_input_files(const std::string& command, const std::vector<PathArg>& inputs);

//! One output's place: the path is not a folder, its folder exists and is writable. Messages
//! start with `command: option "path"`. \throw OptionError (a folder) or IoError (the folder).
void check_output_location(const std::string& command, const PathArg& output);

//! Output files: the folder exists and is writable, the path is not a folder, and no output is
//! the same file as an input or as another output. With `point_cloud`, the extension must be one
//! write_point_cloud() knows (.ply .pcd .xyz .txt). Empty paths are skipped.
void check_output_files(const std::string& command, const std::vector<PathArg>& inputs,
                        const std::vector<PathArg>& outputs, bool point_cloud = true);

}  // namespace scanclean::app
