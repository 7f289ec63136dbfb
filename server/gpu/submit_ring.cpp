#include "gpu/submit_ring.hpp"

namespace hs::gpu {

Result<std::unique_ptr<SubmitRing>> SubmitRing::create(Device& dev, uint32_t slots,
                                                       const std::string& name) {
    if (slots == 0)
        return make_error(ErrorCode::kInvalidArgument, "a submit ring needs at least one slot");
    std::unique_ptr<SubmitRing> r(new SubmitRing(dev));
    VkCommandPoolCreateInfo pci{VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO};
    pci.flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT;
    pci.queueFamilyIndex = dev.queue_family();
    VkCommandPool pool;
    HS_VK_TRY(vkCreateCommandPool(dev.vk(), &pci, nullptr, &pool));
    r->pool_ = CommandPoolHandle(dev.vk(), pool);
    dev.set_name(VK_OBJECT_TYPE_COMMAND_POOL, uint64_t(pool), name + ".pool");
    r->buffers_.resize(slots);
    r->slot_value_.assign(slots, 0);
    VkCommandBufferAllocateInfo ai{VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO};
    ai.commandPool = pool;
    ai.level = VK_COMMAND_BUFFER_LEVEL_PRIMARY;
    ai.commandBufferCount = slots;
    HS_VK_TRY(vkAllocateCommandBuffers(dev.vk(), &ai, r->buffers_.data()));
    VkSemaphoreTypeCreateInfo tci{VK_STRUCTURE_TYPE_SEMAPHORE_TYPE_CREATE_INFO};
    tci.semaphoreType = VK_SEMAPHORE_TYPE_TIMELINE;
    tci.initialValue = 0;
    VkSemaphoreCreateInfo sci{VK_STRUCTURE_TYPE_SEMAPHORE_CREATE_INFO};
    sci.pNext = &tci;
    HS_VK_TRY(vkCreateSemaphore(dev.vk(), &sci, nullptr, &r->timeline_));
    dev.set_name(VK_OBJECT_TYPE_SEMAPHORE, uint64_t(r->timeline_), name + ".timeline");
    // Timestamps, where the queue family writes them.
    uint32_t families = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(dev.physical(), &families, nullptr);
    std::vector<VkQueueFamilyProperties> fp(families);
    vkGetPhysicalDeviceQueueFamilyProperties(dev.physical(), &families, fp.data());
    VkPhysicalDeviceProperties props;
    vkGetPhysicalDeviceProperties(dev.physical(), &props);
    const uint32_t bits =
        dev.queue_family() < families ? fp[dev.queue_family()].timestampValidBits : 0;
    if (bits > 0 && props.limits.timestampPeriod > 0) {
        VkQueryPoolCreateInfo qci{VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO};
        qci.queryType = VK_QUERY_TYPE_TIMESTAMP;
        qci.queryCount = 2 * slots;
        VkQueryPool qp;
        HS_VK_TRY(vkCreateQueryPool(dev.vk(), &qci, nullptr, &qp));
        r->queries_ = QueryPoolHandle(dev.vk(), qp);
        dev.set_name(VK_OBJECT_TYPE_QUERY_POOL, uint64_t(qp), name + ".timestamps");
        r->timestamp_mask_ = bits >= 64 ? ~uint64_t(0) : (uint64_t(1) << bits) - 1;
        r->ns_per_tick_ = double(props.limits.timestampPeriod);
    }
    return r;
}

SubmitRing::~SubmitRing() {
    if (timeline_ != VK_NULL_HANDLE) {
        (void)wait_idle();
        vkDestroySemaphore(device_.vk(), timeline_, nullptr);
    }
}

Result<uint64_t> SubmitRing::submit(const char* label,
                                    const std::function<void(CommandList&)>& record) {
    const uint64_t value = submitted_.load() + 1;
    const size_t slot = size_t(value % buffers_.size());
    uint64_t previous;
    {
        std::lock_guard lock(mutex_);
        previous = slot_value_[slot];
    }
    HS_TRY(wait(previous));  // the command buffer's previous submission is done
    VkCommandBuffer cmd = buffers_[slot];
    HS_VK_TRY(vkResetCommandBuffer(cmd, 0));
    VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    HS_VK_TRY(vkBeginCommandBuffer(cmd, &bi));
    const VkQueryPool qp = queries_.get();
    if (qp) {
        vkCmdResetQueryPool(cmd, qp, uint32_t(2 * slot), 2);
        vkCmdWriteTimestamp2(cmd, VK_PIPELINE_STAGE_2_TOP_OF_PIPE_BIT, qp, uint32_t(2 * slot));
    }
    device_.begin_label(cmd, label);
    CommandList list(device_, cmd, uint32_t(slot));
    record(list);
    device_.end_label(cmd);
    if (qp)
        vkCmdWriteTimestamp2(cmd, VK_PIPELINE_STAGE_2_ALL_COMMANDS_BIT, qp, uint32_t(2 * slot + 1));
    HS_VK_TRY(vkEndCommandBuffer(cmd));
    VkCommandBufferSubmitInfo cbi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_SUBMIT_INFO};
    cbi.commandBuffer = cmd;
    VkSemaphoreSubmitInfo signal{VK_STRUCTURE_TYPE_SEMAPHORE_SUBMIT_INFO};
    signal.semaphore = timeline_;
    signal.value = value;
    signal.stageMask = VK_PIPELINE_STAGE_2_ALL_COMMANDS_BIT;
    VkSubmitInfo2 si{VK_STRUCTURE_TYPE_SUBMIT_INFO_2};
    si.commandBufferInfoCount = 1;
    si.pCommandBufferInfos = &cbi;
    si.signalSemaphoreInfoCount = 1;
    si.pSignalSemaphoreInfos = &signal;
    {
        // Before the submission that resets this slot's queries reaches the device.
        std::lock_guard lock(mutex_);
        slot_value_[slot] = value;
    }
    if (auto r = device_.queue_submit(si); !r) {
        std::lock_guard lock(mutex_);
        slot_value_[slot] = previous;  // never signalled: nobody may wait for it
        return r.error();
    }
    submitted_.store(value);
    return value;
}

Result<void> SubmitRing::wait(uint64_t value) const {
    if (value == 0)
        return {};
    VkSemaphoreWaitInfo wi{VK_STRUCTURE_TYPE_SEMAPHORE_WAIT_INFO};
    wi.semaphoreCount = 1;
    wi.pSemaphores = &timeline_;
    wi.pValues = &value;
    HS_VK_TRY(vkWaitSemaphores(device_.vk(), &wi, UINT64_MAX));
    return {};
}

std::optional<double> SubmitRing::device_ms(uint64_t value) const {
    if (!queries_.get() || value == 0 || completed() < value)
        return std::nullopt;
    const size_t slot = size_t(value % buffers_.size());
    std::lock_guard lock(mutex_);
    if (slot_value_[slot] != value)
        return std::nullopt;  // reused since
    uint64_t ticks[2] = {0, 0};
    if (vkGetQueryPoolResults(device_.vk(), queries_.get(), uint32_t(2 * slot), 2, sizeof ticks,
                              ticks, sizeof(uint64_t), VK_QUERY_RESULT_64_BIT) != VK_SUCCESS)
        return std::nullopt;
    const uint64_t d = (ticks[1] - ticks[0]) & timestamp_mask_;
    return double(d) * ns_per_tick_ * 1e-6;
}

uint64_t SubmitRing::completed() const {
    uint64_t v = 0;
    if (vkGetSemaphoreCounterValue(device_.vk(), timeline_, &v) != VK_SUCCESS)
        return 0;
    return v;
}

}  // namespace hs::gpu
