/// @file atomic_file.h
/// @brief Write-then-rename: every output voxwarp writes appears whole or not at all.
#pragma once

#include <functional>
#include <string>
#include <string_view>

namespace voxwarp {

/// Call `write(tmp_path)` with a temporary path in the same directory as `path`, then rename it to `path`.
/// On any exception the temporary file is removed and `path` is left untouched.
/// @throw IOError when the rename fails or write() leaves no file; rethrows what write() throws.
void write_atomically(const std::string& path, const std::function<void(const std::string& tmp_path)>& write);

/// write_atomically for a file that is `bytes` and nothing else. @throw IOError "PATH: writing WHAT failed".
void write_file_atomically(const std::string& path, std::string_view bytes, const std::string& what);

} // namespace voxwarp
