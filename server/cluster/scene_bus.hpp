// The scene bus of a cluster (`hysar serve --cluster nats://HOST:PORT`, docs/CLUSTER.md): the
// scene JSON under key "scene" of a NATS JetStream key-value bucket, whose revision is the scene
// version every node serves. The only code that includes nats.h (scripts/check_layers.sh).
// Writes are compare-and-set on the revision the writing node has applied; no node applies its
// own write: every node applies what its watch delivers, if and only if it is newer than what it
// has applied. Thread: any; the watch callback runs on the bus's own thread.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <thread>

#include "core/result.hpp"

namespace hs::cluster {

// Why a write failed, for the Error the admin gets.
enum class BusError { kNone, kConflict, kUnavailable };

struct BusWrite {
    uint64_t revision = 0;  // the new revision (kNone)
    BusError error = BusError::kNone;
    std::string message;  // "scene changed concurrently, now version 7", "the scene bus ..."
};

class SceneBus {
public:
    struct Options {
        std::string url;      // nats://HOST:PORT
        std::string node_id;  // heartbeats go to node.<id>
        std::string bucket = "hysar";
        int timeout_ms = 2000;  // per request to the bus
    };
    // Connects and opens (or creates) the bucket. An error naming the URL when the bus cannot be
    // reached at start: a node that cannot learn the current scene must not serve another.
    static Result<std::unique_ptr<SceneBus>> connect(const Options& options);
    ~SceneBus();
    SceneBus(const SceneBus&) = delete;
    SceneBus& operator=(const SceneBus&) = delete;

    // The current scene: its revision and JSON; revision 0 when the bucket holds none.
    Result<std::pair<uint64_t, std::string>> current();
    // Writes `json` if the bucket's revision is still `applied` (0: only if there is none yet).
    BusWrite write(uint64_t applied, const std::string& json);
    // Starts delivering every revision of the scene (the latest when this is called first, then
    // each new one) to `on_scene` on the bus's thread, until destruction; the watch is made
    // again after an outage.
    void watch(std::function<void(uint64_t revision, const std::string& json)> on_scene);
    // Publishes `json` on node.<id> (best effort).
    void heartbeat(const std::string& json);
    bool connected() const;

    // The rule every node applies a delivered revision by (unit-tested): only a newer one.
    static bool newer(uint64_t delivered, uint64_t applied) { return delivered > applied; }

private:
    struct State;
    explicit SceneBus(std::unique_ptr<State> s);
    // `first`: the watcher watch() made (a kvWatcher*, kept out of this header), or null.
    void watch_loop(void* first);
    std::unique_ptr<State> s_;
    std::function<void(uint64_t, const std::string&)> on_scene_;
    std::atomic<bool> stop_{false};
    std::thread thread_;
};

// A write's error as the admin reads it: the conflict names the version now current.
std::string conflict_message(uint64_t current_revision);

}  // namespace hs::cluster
