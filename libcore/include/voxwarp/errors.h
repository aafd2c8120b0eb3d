/// @file errors.h
/// @brief voxwarp's typed exceptions: callers (and the CLI's exit codes) can tell bad input from a
///        resource limit, a failed solve, an I/O failure or a cancelled run.
#pragma once

#include <stdexcept>
#include <string>

namespace voxwarp {

/// Base of every exception voxwarp throws on purpose. The message names the file, field or value.
class Error : public std::runtime_error {
public:
    using std::runtime_error::runtime_error;
};

/// The input (a file, an option, an edit) is malformed or out of range. CLI exit code 2.
class InvalidInput : public Error {
public:
    using Error::Error;
};

/// The request would need more memory (or time) than allowed; the message carries the estimate. Exit code 3.
class ResourceLimit : public Error {
public:
    using Error::Error;
};

/// A numerical solve failed or produced an unusable answer (e.g. a singular constraint system). Exit code 4.
class SolverFailure : public Error {
public:
    using Error::Error;
};

/// A file could not be read or written (missing, permissions, disk full). Exit code 5.
class IOError : public Error {
public:
    using Error::Error;
};

/// The progress callback asked to stop. Exit code 6.
class Cancelled : public Error {
public:
    using Error::Error;
};

} // namespace voxwarp
