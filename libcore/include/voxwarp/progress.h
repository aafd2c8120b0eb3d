/// @file progress.h
/// @brief Progress reporting and cancellation for long operations, in the spirit of OpenVDB's interrupter.
#pragma once

#include <functional>
#include <string_view>

namespace voxwarp {

/// Called now and then from long operations with the stage name and the fraction done in [0, 1].
/// May be called from any thread, but never from two at once for the same operation.
/// Return false to cancel: the operation then throws voxwarp::Cancelled at its next check.
using ProgressCallback = std::function<bool(std::string_view stage, double fraction)>;

/// Reports progress through an optional callback; throws Cancelled when the callback says stop.
/// Thread-safe: report() may be called concurrently, calls to the callback are serialised.
class Progress {
public:
    explicit Progress(ProgressCallback callback = {}, std::string_view stage = {});
    ~Progress();
    Progress(const Progress&) = delete;
    Progress& operator=(const Progress&) = delete;

    /// Set the stage name reported with later fractions.
    void stage(std::string_view name);
    /// Report fraction in [0, 1] of the current stage. @throw Cancelled when the callback returns false.
    void report(double fraction);
    /// Like report() but never throws: returns false once cancelled. For code that must not throw
    /// through a third-party library (OpenVDB's interrupters); call check() after it returns.
    bool poll(double fraction);
    /// True once the callback has returned false (for loops that unwind by themselves).
    bool cancelled() const;
    /// Throw Cancelled if the callback has asked to stop.
    void check() const;

private:
    struct State;
    State* state_;
};

} // namespace voxwarp
