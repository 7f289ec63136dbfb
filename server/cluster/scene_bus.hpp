// The scene bus of a cluster (`hysar serve --cluster nats://HOST:PORT`, docs/CLUSTER.md): the
// scene JSON under key "scene" of a NATS JetStream key-value bucket, whose revision is the scene
// version every node serves. The only code that includes nats.h (scripts/check_layers.sh).
// Every value is signed: "hysar-scene 1 BASE DEADLINE HMAC\n" then the JSON, where BASE is the
// version the write follows, DEADLINE the time (UNIX ms) by which the bus must store it, and
// HMAC is HMAC-SHA256 over "hysar-scene 1\nBASE\nDEADLINE\nJSON", keyed by a key derived from
// the admin token (a refill ends the line with " refill OF", OF the version it puts back, and
// "refill OF\n" follows DEADLINE in the HMAC's input), so only a holder of the admin credential
// changes the scene even on a bus anyone can write; a value not so signed is ignored and counted.
// Writes are compare-and-set on the revision the writing node has applied (or on the unsigned
// values put after it); no node applies its own write: every node applies what its watch delivers,
// if and only if it is newer than what it has applied and follows it (BASE >= applied: an old
// signed value put again is refused). A value the bus stored after its deadline is taken by no
// node, and a write not confirmed in time is reported applied only if the bus stored it in time: a
// refused write never lands later. A burst of values is coalesced to its newest signed one.
// Thread: any; the watch callback runs on one of the bus's two threads (the watch's, and the
// 2-s check's), one call at a time.
#pragma once

#include <atomic>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "core/result.hpp"

namespace hs::cluster {

// Why a write failed, for the Error the admin gets.
enum class BusError { kNone, kConflict, kUnavailable };

struct BusWrite {
    uint64_t revision = 0;     // the new revision (kNone)
    uint64_t deadline_ms = 0;  // the signed deadline of the value written (kNone)
    BusError error = BusError::kNone;
    std::string message;  // "scene changed concurrently, now version 7", "the scene bus ..."
};

class SceneBus {
public:
    struct Options {
        std::string url;          // nats://HOST:PORT or tls://HOST:PORT, without credentials
        std::string node_id;      // heartbeats go to node.<id>
        std::string admin_token;  // signs and checks every value (required)
        std::string bucket = "hysar";
        // Copies of the bucket kept by a NATS cluster when this node creates it (3 on a
        // 3-server cluster: a write is confirmed once a majority stored it).
        int replicas = 1;
        int timeout_ms = 2000;  // per request to the bus
        // At start, how long to wait for a NATS cluster that is still forming (too few servers
        // joined yet to place the bucket's replicas, no leader yet) before giving up.
        int start_wait_ms = 30000;
        // Authentication to NATS, at most one kind: user and password, a token, or a .creds
        // file (a user JWT and its nkey seed).
        std::string user, password, token, creds_file;
        // TLS to the bus: the CA that signed its certificate (empty: the system's); a client
        // certificate and key when the bus asks for one. `tls` turns it on.
        bool tls = false;
        std::string tls_ca, tls_cert, tls_key;
    };
    // A value of the bus, checked.
    struct Value {
        uint64_t revision = 0;     // the bus's revision: the scene version
        uint64_t base = 0;         // the version the write followed (signed)
        uint64_t deadline_ms = 0;  // when the bus had to store it by (signed): its write time
        std::string json;
        bool refill = false;  // a node put it back on a bus found empty or behind (signed)
        uint64_t of = 0;      // a refill: the version it puts back (signed; see stale_refill)
    };
    // What the bus ignored, for /metrics.
    struct Counters {
        std::atomic<uint64_t> unsigned_values{0};    // not signed with the admin credential
        std::atomic<uint64_t> replayed_values{0};    // signed, but not following the applied one
        std::atomic<uint64_t> superseded_values{0};  // coalesced: a newer one came in the burst
        std::atomic<uint64_t> invalid_values{0};     // signed, refused as a SceneUpdate would be
        std::atomic<uint64_t> late_values{0};        // stored after its write's deadline
        std::atomic<uint64_t> stale_refills{0};      // a refill of an older version (stale_refill)
        std::atomic<uint64_t> refills{0};     // the bus came back empty or behind and was refilled
        std::atomic<uint64_t> caught_up{0};   // a scene read directly: the watch was behind
        std::atomic<uint64_t> relabelled{0};  // a refill of the applied scene: not rebuilt
    };
    // How a bus found empty or behind the version a node holds is refilled (unit-tested).
    struct Refill {
        uint64_t revision = 0;  // where the value lands: the next value's revision
        bool ours = true;       // the node's held value; else the bus's own newer write
    };
    // A value's signed parts.
    struct Signed {
        uint64_t base = 0;         // the version the write followed
        uint64_t deadline_ms = 0;  // the bus must have stored it by then (UNIX ms)
        std::string json;
        bool refill = false;
        uint64_t of = 0;  // a refill's: the version it puts back
    };
    // Connects and opens (or creates) the bucket. An error naming the URL when the bus cannot be
    // reached at start: a node that cannot learn the current scene must not serve another.
    static Result<std::unique_ptr<SceneBus>> connect(const Options& options);
    ~SceneBus();
    SceneBus(const SceneBus&) = delete;
    SceneBus& operator=(const SceneBus&) = delete;

    // The signed values the bucket holds, the one to start on first (the greatest BASE, then
    // the newest); empty when it holds none. A node starts on the first that it can serve.
    Result<std::vector<Value>> signed_values();
    // The newest revision this node has seen of any value, signed or not (0: none): after
    // signed_values() found none, whether the key holds only values no node may take.
    uint64_t newest_seen() const { return tail_.load(); }
    // Writes `json`, signed, if the bucket's revision is still `applied` (0: only if there is
    // none yet), or if only unsigned values came after it.
    BusWrite write(uint64_t applied, const std::string& json);
    // Starts delivering the signed revisions of the scene (the latest when this is called
    // first, then each new one; of a burst, only the newest) to `on_scene`, one call at a time
    // from the bus's threads, until destruction; the watch is made again after an outage. A
    // revision may come twice (from the watch and from the check's read of the key): the
    // caller applies only what is newer than what it applied.
    void watch(std::function<void(const Value& value)> on_scene);
    // The value this node serves (it started on it, or applied it from the watch): what it puts
    // back on a bus that comes back empty or behind it (its revisions started again, because
    // its servers restarted without their stores, or the key was deleted), or whose key's
    // history holds no signed value any more (unsigned values pushed them out). Every 2 s a thread
    // of its own reads the key; a bus behind the held version gets its newest scene again, at a
    // revision no node has applied yet, so every node converges on it and nobody's version goes
    // back.
    void hold(const Value& value);
    Value held() const;
    // A signed value that is no scene at all (scene::is_scene_document: every node refuses it
    // alike, whatever its assets, limits or calibration; serve says so): it is not held, a write
    // of this node goes over it (following it), its check puts the held scene back over it while
    // it is the key's current value, above its revision (every node took that revision as its
    // version), and a refill never puts it back. A scene that only this node cannot serve is not
    // passed over: it is held, being another node's scene. A refill is never passed over.
    void pass_over(const Value& v);
    // The rule (unit-tested): nullopt while the bus holds `held` or a later revision. Else the
    // held value goes back, at revision max(held, last + 1) where `last` is the bus's last
    // sequence (the revisions below are purged first); unless the bus's newest signed value
    // `bus_newest` is an admin's write made after the held one (a later deadline, following a
    // version, i.e. not a node's own start-up scene on an empty bus), which then goes back at
    // max(held + 1, last + 1), so the node that held the older one applies it too. Another
    // node's refill never counts as such a write: its deadline is the time of the refill, not of
    // the write it puts back (a lagging node's refill must not outrank a newer held version).
    static std::optional<Refill> plan_refill(const Value& held, uint64_t bus_revision,
                                             uint64_t last, const std::optional<Value>& bus_newest);

    // Stops the watch thread reading, as one blocked inside the NATS client would be, and
    // returns once it has stopped (true; after watch()); or lets it go on (false). The check
    // must then keep the node up to the bus on its own. For the scene-bus tests; nothing else
    // calls it.
    void pause_watch(bool paused);

    // Publishes `json` on node.<id> (best effort).
    void heartbeat(const std::string& json);
    bool connected() const;

    Counters& counters() { return counters_; }
    // The bus's counters in the Prometheus text format (hysar_scene_bus_*).
    std::string metrics_text() const;
    // `url` with any user and password replaced by "***", for logs.
    static std::string redacted(const std::string& url);

    // The rule every node applies a delivered revision by (unit-tested): only a newer one.
    static bool newer(uint64_t delivered, uint64_t applied) { return delivered > applied; }
    // A signed value is applied only if it is newer and follows the applied version.
    static bool follows(const Value& v, uint64_t applied) {
        return newer(v.revision, applied) && v.base >= applied;
    }
    // A refill of a version older than `held`: a lagging node put its older scene back on a bus
    // found empty while another node held a newer one (both refilling at once, the older one's
    // value can land at the newer's revision). No node that holds a newer version applies it,
    // and such a node puts its own back over it, so the cluster converges on the newest.
    // `held` is the version of the scene a node holds (content_version: a relabel keeps it).
    static bool stale_refill(const Value& v, uint64_t held) { return v.refill && v.of < held; }
    // The version whose scene `v` carries: a write's own revision, a refill's OF (the same
    // scene relabelled under a newer revision is still that version's scene, so a node's own
    // refill never makes its older scene outrank a newer one).
    static uint64_t content_version(const Value& v) { return v.refill ? v.of : v.revision; }
    // The signed form of `json` following version `base`, to be stored by `deadline_ms`
    // (unit-tested), and its check: the signed parts, or an error saying why it is refused.
    // `refill_of` > 0: a value put back on a bus found empty or behind, as version refill_of
    // ("... HMAC refill OF").
    static std::string sign(const std::string& admin_token, uint64_t base, uint64_t deadline_ms,
                            const std::string& json, uint64_t refill_of = 0);
    static Result<Signed> verify(const std::string& admin_token, std::string_view value);

private:
    struct State;
    explicit SceneBus(std::unique_ptr<State> s);
    // `first`: the watcher watch() made (a kvWatcher*, kept out of this header), or null.
    void watch_loop(void* first);
    std::unique_ptr<State> s_;
    // A raw entry seen: its signed value, if any; counts and notes the tail revision.
    // `count`: whether an ignored value is counted and logged (not when a refill reads again).
    std::optional<Value> check(uint64_t revision, int64_t stored_ns, std::string_view raw,
                               bool count = true);
    // signed_values(), counting ignored values or not.
    Result<std::vector<Value>> read_signed(bool count);
    // write() with the compare-and-set on `over` when that is later (a value no node takes).
    BusWrite write_on(uint64_t applied, const std::string& json, uint64_t over, int attempts);
    // The 2-s check of the watch: true when the watch must be made again (it is behind the
    // bus, or the bus was refilled).
    bool check_bus(int& behind);
    void check_loop();
    void deliver(const Value& v);
    // Reads the values stored after the newest one seen, up to `revision` (the newest
    // kCatchUpMax at most), and delivers the newest signed one, as the watch would.
    void catch_up(uint64_t revision);
    static constexpr uint64_t kCatchUpMax = 256;
    // Keeps in `newest` the newest write of the two (the watch's rule for a burst).
    static void keep_newest(std::optional<Value>& newest, Value v);
    // Puts the held value back on a bus found empty or behind it; true if the bus changed.
    bool refill();
    // A write the bus did not confirm in time: stored by its deadline (then applied), or never.
    BusWrite settle(const std::string& value, uint64_t deadline_ms);
    std::function<void(const Value&)> on_scene_;
    Counters counters_;
    // The newest revision seen of any value, and of a signed one (writes go on the former when
    // only unsigned values came after the latter).
    std::atomic<uint64_t> tail_{0}, signed_tail_{0};
    std::atomic<uint64_t> passed_over_{0};  // the newest revision pass_over() named
    // The newest revision the watch itself delivered (written by its thread): a watch behind
    // the bus twice in a row is made again.
    std::atomic<uint64_t> watched_{0};
    std::atomic<bool> stop_{false};
    // The watch's thread, and the 2-s check's (check_loop), apart so that a watch blocked
    // inside the client cannot keep the node behind the bus: the check still reads the key,
    // catches up and refills. It asks the watch to be made again through `remake_`.
    std::thread thread_, check_thread_;
    std::atomic<bool> remake_{false};
    std::atomic<bool> watch_paused_{false}, watch_parked_{false};  // pause_watch()
    // The newest revision delivered, or read and passed over in a delivered burst, by either
    // thread: the check's catch-up reads from there, so that a value the watch has read but
    // not yet delivered is weighed with the newer ones (a copy put again must not go first).
    std::atomic<uint64_t> delivered_{0};
    std::atomic<uint64_t> watch_epoch_{0};  // watchers made: the check restarts its count
    // The unsigned value on top whose history the check found still holding a signed one
    // (check thread only).
    uint64_t unsigned_top_read_ = 0;
    std::mutex deliver_mutex_;  // one scene delivered at a time (on_scene_)
    mutable std::mutex held_mutex_;
    Value held_;
};

// A write's error as the admin reads it: the conflict names the version now current.
std::string conflict_message(uint64_t current_revision);

}  // namespace hs::cluster
