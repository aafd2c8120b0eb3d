/// @file resources.h
/// @brief Memory estimates and limits: refuse a request up front instead of dying half-way through it.
#pragma once

#include <cstdint>
#include <string>

namespace voxwarp {

/// Bytes of memory the system can still hand out (MemAvailable), or 0 when unknown.
std::uint64_t available_memory_bytes();

/// Peak resident memory of this process so far (getrusage), bytes.
std::uint64_t peak_resident_bytes();

/// Resident memory of this process now (/proc/self/statm), bytes; 0 when unknown.
std::uint64_t resident_bytes();

/// The limit a request is held to: `limit_bytes`, or, when it is 0, 90 % of the memory available now; the largest
/// value when that is unknown (nothing to check against).
std::uint64_t memory_limit(std::uint64_t limit_bytes);

/// Throw ResourceLimit when `bytes` exceeds `limit_bytes`, or, when `limit_bytes` is 0, 90 % of the
/// memory available now. The message names `what` and gives the estimate, the limit and the override.
void require_memory(std::uint64_t bytes, std::uint64_t limit_bytes, const std::string& what);

/// "1.25 GiB"-style formatting for messages and reports.
std::string format_bytes(std::uint64_t bytes);

} // namespace voxwarp
