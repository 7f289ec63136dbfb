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
    HS_TRY(wait(slot_value_[slot]));  // the command buffer's previous submission is done
    VkCommandBuffer cmd = buffers_[slot];
    HS_VK_TRY(vkResetCommandBuffer(cmd, 0));
    VkCommandBufferBeginInfo bi{VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO};
    bi.flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT;
    HS_VK_TRY(vkBeginCommandBuffer(cmd, &bi));
    device_.begin_label(cmd, label);
    CommandList list(device_, cmd);
    record(list);
    device_.end_label(cmd);
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
    HS_TRY(device_.queue_submit(si));
    slot_value_[slot] = value;
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

uint64_t SubmitRing::completed() const {
    uint64_t v = 0;
    if (vkGetSemaphoreCounterValue(device_.vk(), timeline_, &v) != VK_SUCCESS)
        return 0;
    return v;
}

}  // namespace hs::gpu
