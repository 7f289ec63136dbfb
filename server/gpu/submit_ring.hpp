// Submissions that do not wait (docs/ARCHITECTURE.md, "One VD layer, thread by thread"): a
// timeline semaphore counts completed submissions, and a ring of command buffers holds one per
// submission in flight. The submitter records the next submission while the device runs the
// previous ones; whoever needs a result waits for its timeline value. Each submission is
// bracketed by two timestamps where the queue has them, so device_ms() tells how long the
// device spent on it, apart from the time it waited behind the others.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "gpu/commands.hpp"
#include "gpu/device.hpp"

namespace hs::gpu {

class SubmitRing {
public:
    // `slots` submissions may be in flight at once; a further submit() waits for the oldest.
    static Result<std::unique_ptr<SubmitRing>> create(Device& device, uint32_t slots,
                                                      const std::string& name);
    ~SubmitRing();  // waits for every submission
    SubmitRing(const SubmitRing&) = delete;
    SubmitRing& operator=(const SubmitRing&) = delete;

    // Records with `record` into the next command buffer and submits it without waiting;
    // returns the timeline value its completion signals. Thread: one submitter.
    Result<uint64_t> submit(const char* label, const std::function<void(CommandList&)>& record);
    // Blocks until the submission of `value` completed. Thread: any.
    Result<void> wait(uint64_t value) const;
    // The highest value whose submission completed. Thread: any.
    uint64_t completed() const;
    // The value of the latest submission (0: none yet). Thread: any.
    uint64_t submitted() const { return submitted_.load(); }
    Result<void> wait_idle() const { return wait(submitted()); }
    // Milliseconds the device spent on the completed submission of `value`, from its first to
    // its last command (Vulkan timestamps); nullopt when the queue has no timestamps, the
    // submission has not completed, or its command buffer has been reused. Thread: any.
    std::optional<double> device_ms(uint64_t value) const;

private:
    explicit SubmitRing(Device& device) : device_(device) {}
    Device& device_;
    CommandPoolHandle pool_;
    VkSemaphore timeline_ = VK_NULL_HANDLE;
    std::vector<VkCommandBuffer> buffers_;
    std::vector<uint64_t> slot_value_;  // the value each command buffer last signals (mutex_)
    QueryPoolHandle queries_;           // two per slot; null: no timestamps on this queue
    uint64_t timestamp_mask_ = 0;       // the queue's valid bits
    double ns_per_tick_ = 0;
    // Guards slot_value_ against submit() reusing a slot while device_ms() reads its queries.
    mutable std::mutex mutex_;
    std::atomic<uint64_t> submitted_{0};
};

}  // namespace hs::gpu
