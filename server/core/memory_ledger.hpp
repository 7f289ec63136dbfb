// What the server holds for its scene versions, counted by the server itself rather than read
// from the process's resident set (which, under a sanitizer, includes its quarantine, and on
// any allocator includes freed memory not yet returned): bytes of CPU scene data, bytes of
// device memory allocated for scene resources, and the scene versions alive
// (docs/OPERATIONS.md, "Scene memory").
//
// Bytes are counted where they are allocated and freed: a MemoryCharge is held by the object
// that owns the memory and lives exactly as long as it, so a version that is never freed stays
// on the ledger. Thread: any (atomics); a charge is moved or reset by its owner's thread.
#pragma once

#include <atomic>
#include <cstdint>
#include <memory>
#include <utility>

namespace hs {

// Live bytes (or items) under one name, with the number of charges holding them.
class MemoryCounter {
public:
    void add(int64_t bytes, int64_t holders) {
        raise(peak_bytes_, bytes_.fetch_add(bytes, std::memory_order_relaxed) + bytes);
        raise(peak_holders_, holders_.fetch_add(holders, std::memory_order_relaxed) + holders);
    }
    int64_t bytes() const { return bytes_.load(std::memory_order_relaxed); }
    int64_t holders() const { return holders_.load(std::memory_order_relaxed); }
    // The most there ever were at once.
    int64_t peak_bytes() const { return peak_bytes_.load(std::memory_order_relaxed); }
    int64_t peak_holders() const { return peak_holders_.load(std::memory_order_relaxed); }

private:
    static void raise(std::atomic<int64_t>& peak, int64_t now) {
        int64_t seen = peak.load(std::memory_order_relaxed);
        while (now > seen && !peak.compare_exchange_weak(seen, now, std::memory_order_relaxed)) {
        }
    }
    std::atomic<int64_t> bytes_{0}, peak_bytes_{0};
    std::atomic<int64_t> holders_{0}, peak_holders_{0};
};

// `bytes` counted on a counter for as long as the charge lives (null counter: nothing is
// counted). Move-only; set() changes the amount of a live charge.
class MemoryCharge {
public:
    MemoryCharge() = default;
    MemoryCharge(MemoryCounter* counter, int64_t bytes) : counter_(counter), bytes_(bytes) {
        if (counter_)
            counter_->add(bytes_, 1);
    }
    MemoryCharge(const MemoryCharge&) = delete;
    MemoryCharge& operator=(const MemoryCharge&) = delete;
    MemoryCharge(MemoryCharge&& o) noexcept
        : counter_(std::exchange(o.counter_, nullptr)), bytes_(std::exchange(o.bytes_, 0)) {}
    MemoryCharge& operator=(MemoryCharge&& o) noexcept {
        if (this != &o) {
            reset();
            counter_ = std::exchange(o.counter_, nullptr);
            bytes_ = std::exchange(o.bytes_, 0);
        }
        return *this;
    }
    ~MemoryCharge() { reset(); }

    void set(int64_t bytes) {
        if (counter_)
            counter_->add(bytes - bytes_, 0);
        bytes_ = bytes;
    }
    void reset() {
        if (counter_)
            counter_->add(-bytes_, -1);
        counter_ = nullptr;
        bytes_ = 0;
    }
    int64_t bytes() const { return bytes_; }
    bool active() const { return counter_ != nullptr; }

private:
    MemoryCounter* counter_ = nullptr;
    int64_t bytes_ = 0;
};

// `value`, shared, counted as `bytes` on `counter` (null: nowhere) until its last holder lets go
// of it. `keep` (optional) is held as long: the counter's owner, when holders may outlive it.
template <typename T>
std::shared_ptr<const T> make_charged(T value, MemoryCounter* counter, int64_t bytes,
                                      std::shared_ptr<const void> keep = nullptr) {
    struct Held {
        T value;
        std::shared_ptr<const void> keep;
        MemoryCharge charge;  // released first
    };
    auto held = std::make_shared<Held>(
        Held{std::move(value), std::move(keep), MemoryCharge(counter, bytes)});
    const T* raw = &held->value;
    return std::shared_ptr<const T>(std::move(held), raw);
}

// The scene's memory, by kind. Owned by the server (stream::Server), which outlives every
// charge on it; the render thread, the network thread and the encoders charge it.
struct SceneLedger {
    MemoryCounter cpu;        // scene data on the CPU: meshes, textures, captured images,
                              // the renderer's levels of detail, encoded projector frames
    MemoryCounter device;     // device memory: mesh and uniform buffers, textures, the
                              // renderer's own targets (holders: allocations)
    MemoryCounter versions;   // scene versions alive (a renderer built for one; bytes unused)
    MemoryCounter pipelines;  // their pipelines (holders; the driver's memory, not counted)
    // The command buffers their planning threads record layers into (gpu::SecondaryBuffers;
    // holders: buffers, each with a command pool of its own; the driver's memory, not counted).
    MemoryCounter command_buffers;
    std::atomic<uint64_t> versions_built{0}, versions_freed{0};
};

}  // namespace hs
