#include <voxwarp/errors.h>
#include <voxwarp/progress.h>

#include <atomic>
#include <mutex>
#include <string>

namespace voxwarp {

struct Progress::State {
    ProgressCallback callback;
    std::string stage;
    std::mutex mutex;
    std::atomic<bool> cancelled{false};
};

Progress::Progress(ProgressCallback callback, std::string_view stage) : state_(new State) {
    state_->callback = std::move(callback);
    state_->stage = stage;
}

Progress::~Progress() { delete state_; }

void Progress::stage(std::string_view name) {
    std::lock_guard lock(state_->mutex);
    state_->stage = name;
}

bool Progress::poll(double fraction) {
    if (state_->callback && !state_->cancelled.load(std::memory_order_relaxed)) {
        std::lock_guard lock(state_->mutex);
        if (!state_->callback(state_->stage, fraction < 0 ? 0 : (fraction > 1 ? 1 : fraction)))
            state_->cancelled = true;
    }
    return !cancelled();
}

void Progress::report(double fraction) {
    poll(fraction);
    check();
}

bool Progress::cancelled() const { return state_->cancelled.load(std::memory_order_relaxed); }

void Progress::check() const {
    if (cancelled()) throw Cancelled("cancelled during " + state_->stage);
}

} // namespace voxwarp
