#include "cluster/scene_bus.hpp"

#include <nats/nats.h>
#include <openssl/crypto.h>
#include <openssl/evp.h>
#include <openssl/hmac.h>
#include <openssl/sha.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <mutex>
#include <thread>
#include <utility>
#include <vector>

#include <fmt/format.h>

#include "core/log.hpp"

namespace hs::cluster {

namespace {

constexpr const char* kKey = "scene";
constexpr std::string_view kMagic = "hysar-scene 1 ";
constexpr size_t kMaxValue = (size_t(1) << 20) + 256;  // a SceneUpdate's limit and the header

std::string status_text(natsStatus s) {
    const char* last = nats_GetLastError(nullptr);
    return last && *last ? last : natsStatus_GetText(s);
}

// The wall clock in milliseconds since the UNIX epoch: a write's deadline, which the bus's own
// timestamp of the stored value is held to.
uint64_t now_unix_ms() {
    return uint64_t(std::chrono::duration_cast<std::chrono::milliseconds>(
                        std::chrono::system_clock::now().time_since_epoch())
                        .count());
}

// How far the bus's clock may be behind the writer's (NTP keeps it far less): a writer told
// "refused" checks the bus only this long after the deadline.
constexpr uint64_t kClockMarginMs = 500;
// How long an unconfirmed writer keeps asking a bus that does not answer whether it stored the
// value in time, before it says the outcome is unknown.
constexpr uint64_t kSettleLookMs = 15000;

// Raises `to` to `revision` if that is newer (any thread).
void raise_to(std::atomic<uint64_t>& to, uint64_t revision) {
    for (uint64_t t = to.load(); revision > t && !to.compare_exchange_weak(t, revision);) {
    }
}

// HMAC-SHA256 over "hysar-scene 1\nBASE\nDEADLINE\nJSON" with a key derived from the admin
// token (so that the token itself is never the key of anything else), as 64 hex digits.
std::string mac(const std::string& admin_token, uint64_t base, uint64_t deadline_ms,
                uint64_t refill_of, std::string_view json) {
    const std::string label = "hysar scene bus key\n" + admin_token;
    unsigned char key[SHA256_DIGEST_LENGTH];
    SHA256(reinterpret_cast<const unsigned char*>(label.data()), label.size(), key);
    const std::string head = fmt::format("hysar-scene 1\n{}\n{}\n{}", base, deadline_ms,
                                         refill_of ? fmt::format("refill {}\n", refill_of) : "");
    unsigned char out[EVP_MAX_MD_SIZE];
    unsigned int len = 0;
    std::string data;
    data.reserve(head.size() + json.size());
    data.append(head).append(json);
    HMAC(EVP_sha256(), key, sizeof key, reinterpret_cast<const unsigned char*>(data.data()),
         data.size(), out, &len);
    static constexpr char kHex[] = "0123456789abcdef";
    std::string hex;
    for (unsigned int i = 0; i < len; ++i) {
        hex.push_back(kHex[out[i] >> 4]);
        hex.push_back(kHex[out[i] & 15]);
    }
    return hex;
}

// Logs the first of a burst of refused values at once and the rest in one line per 10 s.
class BurstLog {
public:
    void note(const std::string& what) {
        std::lock_guard lock(mutex_);
        const auto now = std::chrono::steady_clock::now();
        if (now - last_ < std::chrono::seconds(10)) {
            ++held_;
            return;
        }
        if (held_ > 0)
            log::warn("scene bus: {} more value(s) ignored in the last burst", held_);
        log::warn("scene bus: {}", what);
        held_ = 0;
        last_ = now;
    }

private:
    std::mutex mutex_;
    std::chrono::steady_clock::time_point last_{};
    uint64_t held_ = 0;
};

BurstLog& burst_log() {
    static BurstLog log;
    return log;
}

}  // namespace

std::string SceneBus::sign(const std::string& admin_token, uint64_t base, uint64_t deadline_ms,
                           const std::string& json, uint64_t refill_of) {
    return fmt::format("{}{} {} {}{}\n{}", kMagic, base, deadline_ms,
                       mac(admin_token, base, deadline_ms, refill_of, json),
                       refill_of ? fmt::format(" refill {}", refill_of) : "", json);
}

Result<SceneBus::Signed> SceneBus::verify(const std::string& admin_token, std::string_view value) {
    if (value.size() > kMaxValue)
        return make_error(ErrorCode::kInvalidArgument,
                          fmt::format("a value of {} bytes (at most {})", value.size(), kMaxValue));
    const auto eol = value.find('\n');
    if (value.substr(0, kMagic.size()) != kMagic || eol == std::string_view::npos || eol > 120)
        return make_error(ErrorCode::kInvalidArgument,
                          "a value not signed with the admin credential");
    std::string_view head = value.substr(kMagic.size(), eol - kMagic.size());
    // BASE and DEADLINE: decimal numbers, each followed by a space.
    auto number = [&head](uint64_t& n) {
        const auto space = head.find(' ');
        const std::string_view text = head.substr(0, space);
        if (space == std::string_view::npos || text.empty() || text.size() > 19)
            return false;
        n = 0;
        for (char c : text) {
            if (c < '0' || c > '9')
                return false;
            n = n * 10 + uint64_t(c - '0');
        }
        head.remove_prefix(space + 1);
        return true;
    };
    Signed out;
    const bool ok = number(out.base) && number(out.deadline_ms);
    // The HMAC, then " refill OF" on a value put back on a bus found empty or behind, OF (> 0)
    // the version it puts back.
    bool of_ok = true;
    if (const auto r = head.find(" refill "); r != std::string_view::npos) {
        std::string_view of = head.substr(r + 8);
        out.refill = true;
        of_ok = !of.empty() && of.size() <= 19;
        for (char c : of) {
            of_ok = of_ok && c >= '0' && c <= '9';
            out.of = out.of * 10 + uint64_t(c - '0');
        }
        of_ok = of_ok && out.of > 0;
        head = head.substr(0, r);
    }
    out.json = std::string(value.substr(eol + 1));
    const std::string want =
        ok && of_ok ? mac(admin_token, out.base, out.deadline_ms, out.of, out.json) : "";
    if (!ok || !of_ok || want.empty() || head.size() != want.size() ||
        CRYPTO_memcmp(head.data(), want.data(), want.size()) != 0)
        return make_error(ErrorCode::kInvalidArgument,
                          "a value not signed with the admin credential");
    return out;
}

namespace {

// What the key's current value `e` is to a node that holds version `held` (0: none yet): a value
// it may leave there, another node's refill of an older version (SceneBus::stale_refill), or a
// value not signed with the admin credential (put over only where no signed value is left in
// the key's history).
enum class Top { kSigned, kStaleRefill, kUnsigned };
Top top_of(kvEntry* e, const std::string& admin_token, uint64_t held) {
    if (held == 0 || kvEntry_Operation(e) != kvOp_Put)
        return Top::kSigned;
    auto v = SceneBus::verify(
        admin_token,
        std::string_view(static_cast<const char*>(kvEntry_Value(e)), size_t(kvEntry_ValueLen(e))));
    if (!v)
        return Top::kUnsigned;
    return v->refill && v->of < held ? Top::kStaleRefill : Top::kSigned;
}

}  // namespace

std::string SceneBus::redacted(const std::string& url) {
    const auto scheme = url.find("://");
    const auto from = scheme == std::string::npos ? 0 : scheme + 3;
    const auto at = url.find('@', from);
    if (at == std::string::npos)
        return url;
    return url.substr(0, from) + "***" + url.substr(at);
}

std::string SceneBus::metrics_text() const {
    std::string t =
        "# HELP hysar_scene_bus_ignored_values_total Values on the scene bus this node did not "
        "apply, by why: unsigned (not signed with the admin credential), replayed (signed, but "
        "an older write put again), superseded (a newer one came in the same burst), invalid "
        "(refused as a SceneUpdate would be), late (stored after its write's deadline), "
        "stale_refill (a node's refill of a version older than this node's).\n"
        "# TYPE hysar_scene_bus_ignored_values_total counter\n";
    const std::pair<const char*, uint64_t> rows[] = {
        {"unsigned", counters_.unsigned_values.load()},
        {"replayed", counters_.replayed_values.load()},
        {"superseded", counters_.superseded_values.load()},
        {"invalid", counters_.invalid_values.load()},
        {"late", counters_.late_values.load()},
        {"stale_refill", counters_.stale_refills.load()}};
    for (const auto& [why, n] : rows)
        t += fmt::format("hysar_scene_bus_ignored_values_total{{why=\"{}\"}} {}\n", why, n);
    t += fmt::format(
        "# HELP hysar_scene_bus_refills_total Times this node found the bus empty or behind the "
        "scene version it holds (its servers restarted without their stores, or the key was "
        "deleted) and put the newest scene back.\n"
        "# TYPE hysar_scene_bus_refills_total counter\nhysar_scene_bus_refills_total {}\n",
        counters_.refills.load());
    t += fmt::format(
        "# HELP hysar_scene_bus_caught_up_total Scenes this node read from the bus directly "
        "because its watch was behind (its consumer lived on a bus server that died, and the "
        "servers had not yet elected a new JetStream leader to make it again).\n"
        "# TYPE hysar_scene_bus_caught_up_total counter\nhysar_scene_bus_caught_up_total {}\n",
        counters_.caught_up.load());
    t += fmt::format(
        "# HELP hysar_scene_bus_relabelled_total Refills of the scene this node had applied "
        "(another node, or this one, put it back on a bus found empty): applied as the new "
        "version without building the scene again.\n"
        "# TYPE hysar_scene_bus_relabelled_total counter\nhysar_scene_bus_relabelled_total {}\n",
        counters_.relabelled.load());
    t += fmt::format(
        "# HELP hysar_scene_bus_connected Whether this node is connected to the scene bus.\n"
        "# TYPE hysar_scene_bus_connected gauge\nhysar_scene_bus_connected {}\n",
        connected() ? 1 : 0);
    return t;
}

std::string conflict_message(uint64_t current_revision) {
    return fmt::format("scene changed concurrently, now version {}; fetch it and try again",
                       current_revision);
}

namespace {

// Makes the bucket (or opens it when another node just made it with the same settings).
natsStatus create_bucket(kvStore** kv, jsCtx* js, const SceneBus::Options& o) {
    kvConfig cfg;
    kvConfig_Init(&cfg);
    cfg.Bucket = o.bucket.c_str();
    // Some history, so that a node starts on the newest signed value even when unsigned ones
    // were put after it.
    cfg.History = 16;
    cfg.MaxValueSize = int32_t(kMaxValue);
    cfg.Replicas = o.replicas;
    return js_CreateKeyValue(kv, js, &cfg);
}

}  // namespace

struct SceneBus::State {
    Options options;
    // Set by the client's thread on a reconnect: the watch is made again a second later (its
    // consumer may have lived on a server that is gone).
    std::atomic<bool> reconnected{false};
    natsConnection* nc = nullptr;
    jsCtx* js = nullptr;
    kvStore* kv = nullptr;
    ~State() {
        if (kv)
            kvStore_Destroy(kv);
        if (js)
            jsCtx_Destroy(js);
        if (nc) {
            natsConnection_Close(nc);
            natsConnection_Destroy(nc);
        }
    }
};

SceneBus::SceneBus(std::unique_ptr<State> s) : s_(std::move(s)) {}

SceneBus::~SceneBus() {
    stop_ = true;
    if (thread_.joinable())
        thread_.join();
    if (check_thread_.joinable())
        check_thread_.join();
}

Result<std::unique_ptr<SceneBus>> SceneBus::connect(const Options& o) {
    if (o.admin_token.empty())
        return make_error(ErrorCode::kInvalidArgument,
                          "--cluster: the scene bus needs the admin token (--admin-token-file): "
                          "it signs and checks every scene");
    auto st = std::make_unique<State>();
    st->options = o;
    const std::string shown = redacted(o.url);
    natsOptions* opts = nullptr;
    natsStatus s = natsOptions_Create(&opts);
    // One URL, or every server of a NATS cluster, comma-separated.
    std::vector<std::string> urls;
    for (size_t from = 0; from <= o.url.size();) {
        const size_t comma = std::min(o.url.find(',', from), o.url.size());
        if (comma > from)
            urls.push_back(o.url.substr(from, comma - from));
        from = comma + 1;
    }
    std::vector<const char*> servers;
    for (const auto& u : urls) servers.push_back(u.c_str());
    if (s == NATS_OK)
        s = natsOptions_SetServers(opts, servers.data(), int(servers.size()));
    if (s == NATS_OK)
        s = natsOptions_SetTimeout(opts, o.timeout_ms);
    // Named in the bus's monitoring (connz): which connection is which node.
    const std::string name = "hysar node " + o.node_id;
    if (s == NATS_OK)
        s = natsOptions_SetName(opts, name.c_str());
    if (s == NATS_OK)
        s = natsOptions_SetMaxReconnect(opts, -1);  // forever: nodes outlive a bus outage
    if (s == NATS_OK)
        s = natsOptions_SetReconnectWait(opts, 250);
    if (s == NATS_OK)
        s = natsOptions_SetReconnectedCB(
            opts,
            [](natsConnection*, void* state) { static_cast<State*>(state)->reconnected = true; },
            st.get());
    if (s == NATS_OK && !o.user.empty())
        s = natsOptions_SetUserInfo(opts, o.user.c_str(), o.password.c_str());
    if (s == NATS_OK && !o.token.empty())
        s = natsOptions_SetToken(opts, o.token.c_str());
    if (s == NATS_OK && !o.creds_file.empty())
        s = natsOptions_SetUserCredentialsFromFiles(opts, o.creds_file.c_str(), nullptr);
    if (s == NATS_OK && o.tls)
        s = natsOptions_SetSecure(opts, true);
    if (s == NATS_OK && !o.tls_ca.empty())
        s = natsOptions_LoadCATrustedCertificates(opts, o.tls_ca.c_str());
    if (s == NATS_OK && !o.tls_cert.empty())
        s = natsOptions_LoadCertificatesChain(opts, o.tls_cert.c_str(), o.tls_key.c_str());
    if (s == NATS_OK)
        s = natsConnection_Connect(&st->nc, opts);
    if (opts)
        natsOptions_Destroy(opts);
    if (s != NATS_OK)
        return make_error(ErrorCode::kIo, fmt::format("--cluster {}: cannot connect to the scene "
                                                      "bus: {}",
                                                      shown, status_text(s)));
    jsOptions jo;
    jsOptions_Init(&jo);
    jo.Wait = o.timeout_ms;
    s = natsConnection_JetStream(&st->js, st->nc, &jo);
    // A NATS cluster that is still forming (its servers started together with this node)
    // answers a replicated bucket with "no suitable peers" until enough of them joined, or
    // with a timeout while it elects a leader: waited for, up to start_wait_ms, shown once.
    const auto forming = [](natsStatus e) {
        const std::string why = status_text(e);
        return e == NATS_TIMEOUT || why.find("no suitable peers") != std::string::npos ||
               why.find("temporarily unavailable") != std::string::npos;
    };
    // Each try may itself wait up to two request timeouts (open, then create): the last try
    // starts early enough to end by the deadline (or, for a wait of no more than that, halfway).
    const auto start = std::chrono::steady_clock::now();
    const auto until =
        start + std::chrono::milliseconds(std::max<int64_t>(
                    o.start_wait_ms - 2 * int64_t(o.timeout_ms), o.start_wait_ms / 2));
    for (bool shown_wait = false; s == NATS_OK;) {
        s = js_KeyValue(&st->kv, st->js, o.bucket.c_str());
        if (s == NATS_NOT_FOUND)
            s = create_bucket(&st->kv, st->js, o);
        if (s == NATS_OK || !forming(s) || std::chrono::steady_clock::now() >= until)
            break;
        if (!std::exchange(shown_wait, true))
            log::info("scene bus: waiting up to {} s for the bus's JetStream cluster ({})",
                      (o.start_wait_ms + 999) / 1000, status_text(s));
        std::this_thread::sleep_for(std::chrono::milliseconds(250));
        s = NATS_OK;
    }
    if (s != NATS_OK && o.replicas > 1 &&
        status_text(s).find("no suitable peers") != std::string::npos)
        return make_error(
            ErrorCode::kIo,
            fmt::format(
                "--cluster {}: the bus cannot place the bucket '{}' on {} servers "
                "(--cluster-replicas {}) after {:.0f} s: does its JetStream cluster "
                "have that many servers, all up? ({})",
                shown, o.bucket, o.replicas, o.replicas,
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
                status_text(s)));
    if (s != NATS_OK)
        return make_error(ErrorCode::kIo,
                          fmt::format("--cluster {}: cannot open the key-value bucket '{}' "
                                      "(is JetStream on? nats-server -js): {}",
                                      shown, o.bucket, status_text(s)));
    // A bucket made earlier keeps its replica count: one with fewer copies than asked is
    // named, since a write it confirms may then sit on fewer servers than the operator thinks.
    const std::string stream = "KV_" + o.bucket;
    jsStreamInfo* si = nullptr;
    if (js_GetStreamInfo(&si, st->js, stream.c_str(), nullptr, nullptr) == NATS_OK && si) {
        const int have = si->Config ? int(si->Config->Replicas) : 0;
        jsStreamInfo_Destroy(si);
        if (have > 0 && have < o.replicas)
            log::warn(
                "scene bus: the bucket '{}' exists with {} replica(s), fewer than the {} asked "
                "(--cluster-replicas): it keeps {} (raise it with `nats stream edit {} "
                "--replicas {}`)",
                o.bucket, have, o.replicas, have, stream, o.replicas);
    }
    return std::unique_ptr<SceneBus>(new SceneBus(std::move(st)));
}

bool SceneBus::connected() const {
    return natsConnection_Status(s_->nc) == NATS_CONN_STATUS_CONNECTED;
}

std::optional<SceneBus::Value> SceneBus::check(uint64_t revision, int64_t stored_ns,
                                               std::string_view raw, bool count) {
    // The newest revision seen (tail_) and the newest signed one (signed_tail_). A writer reads
    // tail_ before signed_tail_ and writes over what lies between as unsigned, so a signed
    // value raises signed_tail_ before tail_: a writer never sees it in the tail and not in the
    // signed tail (it would write over a value every node takes, with an older base that every
    // node then refuses: an acknowledged update lost).
    auto v = verify(s_->options.admin_token, raw);
    if (!v) {
        raise_to(tail_, revision);
        if (count) {
            ++counters_.unsigned_values;
            burst_log().note(fmt::format("version {} ignored: {}", revision, v.error().message));
        }
        return std::nullopt;
    }
    // Stored after its deadline: its writer was told the write failed, so no node takes it.
    if (stored_ns > 0 && uint64_t(stored_ns / 1000000) > v->deadline_ms) {
        raise_to(tail_, revision);
        if (!count)
            return std::nullopt;
        ++counters_.late_values;
        burst_log().note(
            fmt::format("version {} ignored: the bus stored it {} ms after its "
                        "write's deadline (its writer was told it failed)",
                        revision, uint64_t(stored_ns / 1000000) - v->deadline_ms));
        return std::nullopt;
    }
    raise_to(signed_tail_, revision);
    raise_to(tail_, revision);
    return Value{revision, v->base, v->deadline_ms, std::move(v->json), v->refill, v->of};
}

Result<std::vector<SceneBus::Value>> SceneBus::signed_values() {
    return read_signed(true);
}

Result<std::vector<SceneBus::Value>> SceneBus::read_signed(bool count) {
    kvEntryList list{};
    kvWatchOptions wo;
    kvWatchOptions_Init(&wo);
    wo.IgnoreDeletes = true;
    const natsStatus s = kvStore_History(&list, s_->kv, kKey, &wo);
    std::vector<Value> out;
    if (s == NATS_NOT_FOUND)
        return out;
    if (s != NATS_OK)
        return make_error(ErrorCode::kIo, "the scene bus: " + status_text(s));
    for (int i = 0; i < list.Count; ++i) {
        kvEntry* e = list.Entries[i];
        if (kvEntry_Operation(e) != kvOp_Put)
            continue;
        auto v = check(kvEntry_Revision(e), kvEntry_Created(e),
                       std::string_view(static_cast<const char*>(kvEntry_Value(e)),
                                        size_t(kvEntry_ValueLen(e))),
                       count);
        if (v)
            out.push_back(std::move(*v));
    }
    kvEntryList_Destroy(&list);
    // An old value put again has an old base: the greatest base is the newest write. Of the
    // values with that base the first stored is the write; a later one is a copy put again
    // (within its deadline), which the nodes that applied the first refuse as replayed, so a
    // node that took the copy would refuse the next write, which follows the first.
    std::sort(out.begin(), out.end(), [](const Value& a, const Value& b) {
        return a.base != b.base ? a.base > b.base : a.revision < b.revision;
    });
    return out;
}

BusWrite SceneBus::write(uint64_t applied, const std::string& json) {
    return write_on(applied, json, 0, 3);
}

BusWrite SceneBus::write_on(uint64_t applied, const std::string& json, uint64_t over,
                            int attempts) {
    // While disconnected the client would buffer the write and send it after the reconnect,
    // long after the admin was told it failed: refuse it here instead.
    if (!connected())
        return {0, 0, BusError::kUnavailable,
                "the scene bus is unavailable (not connected to " + redacted(s_->options.url) +
                    "); the running scene stays"};
    // Unsigned values after the applied version, and a signed value that is no scene
    // (pass_over), are no one's write: write over them.
    const uint64_t passed = passed_over_.load();
    const uint64_t tail = tail_.load(), signed_tail = signed_tail_.load();
    const uint64_t expected =
        std::max(tail > applied && signed_tail <= std::max(applied, passed) ? tail : applied, over);
    // Over a value passed over, the write follows it: every node took its revision as its
    // version.
    const uint64_t base =
        expected > applied && passed > applied ? std::min(passed, expected) : applied;
    // The bus must store it by the deadline, or no node takes it: a write the admin is told
    // failed never lands later.
    const uint64_t deadline = now_unix_ms() + uint64_t(s_->options.timeout_ms);
    const std::string value = sign(s_->options.admin_token, base, deadline, json);
    uint64_t rev = 0;
    const natsStatus s =
        expected == 0
            ? kvStore_Create(&rev, s_->kv, kKey, value.data(), int(value.size()))
            : kvStore_Update(&rev, s_->kv, kKey, value.data(), int(value.size()), expected);
    if (s == NATS_OK) {
        // Confirmed, but every node holds it to the deadline by the bus's clock: a writer whose
        // clock is behind must not report a write that no node takes.
        kvEntry* e = nullptr;
        if (kvStore_GetRevision(&e, s_->kv, kKey, rev) == NATS_OK) {
            const uint64_t stored_ms = uint64_t(std::max<int64_t>(kvEntry_Created(e), 0) / 1000000);
            kvEntry_Destroy(e);
            if (stored_ms > deadline)
                return {0, 0, BusError::kUnavailable,
                        fmt::format("the scene bus stored the write {} ms after its deadline "
                                    "(is this node's clock behind the bus's? NTP): no node takes "
                                    "it; the running scene stays",
                                    stored_ms - deadline)};
        }
        return {rev, deadline, BusError::kNone, ""};
    }
    const std::string why = status_text(s);
    if (why.find("wrong last sequence") != std::string::npos ||
        why.find("key exists") != std::string::npos) {
        kvEntry* e = nullptr;
        uint64_t now = applied + 1;
        bool takeable = true;  // by every node: a real concurrent write
        if (kvStore_Get(&e, s_->kv, kKey) == NATS_OK) {
            now = kvEntry_Revision(e);
            auto v = verify(s_->options.admin_token,
                            std::string_view(static_cast<const char*>(kvEntry_Value(e)),
                                             size_t(kvEntry_ValueLen(e))));
            takeable =
                v && v->base >= applied && now != passed_over_.load() &&
                uint64_t(std::max<int64_t>(kvEntry_Created(e), 0) / 1000000) <= v->deadline_ms;
            kvEntry_Destroy(e);
        }
        // Over a value no node takes (unsigned, late, an old one put again, or no scene at
        // all): written on it.
        if (!takeable && now > expected && attempts > 1)
            return write_on(applied, json, now, attempts - 1);
        return {0, 0, BusError::kConflict, conflict_message(now)};
    }
    if (s == NATS_TIMEOUT)
        return settle(value, deadline);
    return {0, 0, BusError::kUnavailable,
            "the scene bus is unavailable (" + why + "); the running scene stays"};
}

BusWrite SceneBus::settle(const std::string& value, uint64_t deadline_ms) {
    // Unconfirmed: once no copy of it can be taken any more (the deadline and the clock margin
    // passed), it was either stored in time (then it is the new version, taken by every node)
    // or it never will be. The bus may be down then (killed mid-write): it is asked again
    // until it answers, for as long as kSettleLookMs, since a value it stored in time will be
    // taken by the nodes when it is back.
    const uint64_t until = deadline_ms + kClockMarginMs;
    while (now_unix_ms() < until && !stop_)
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    bool looked = false;
    uint64_t stored = 0;
    for (const uint64_t give_up = now_unix_ms() + kSettleLookMs; !looked && !stop_;) {
        kvEntryList list{};
        kvWatchOptions wo;
        kvWatchOptions_Init(&wo);
        wo.IgnoreDeletes = true;
        const natsStatus s = kvStore_History(&list, s_->kv, kKey, &wo);
        // Only a history read counts as a look: a bus that answers it has no key (lost its
        // store) cannot say whether it had stored the value in time.
        if (s == NATS_OK) {
            looked = true;
            for (int i = 0; i < list.Count; ++i) {
                kvEntry* e = list.Entries[i];
                const int64_t at = kvEntry_Created(e);
                if (size_t(kvEntry_ValueLen(e)) == value.size() &&
                    std::memcmp(kvEntry_Value(e), value.data(), value.size()) == 0 &&
                    uint64_t(at / 1000000) <= deadline_ms)
                    stored = kvEntry_Revision(e);
            }
            kvEntryList_Destroy(&list);
        } else if (now_unix_ms() >= give_up) {
            break;
        } else {
            std::this_thread::sleep_for(std::chrono::milliseconds(250));
        }
    }
    if (stored != 0)
        return {stored, deadline_ms, BusError::kNone, ""};
    if (!looked)
        return {0, 0, BusError::kUnavailable,
                fmt::format("the scene bus did not confirm the write within {} ms and could not "
                            "be reached for {} s after to look whether it stored it: the outcome "
                            "is unknown (if the bus stored it in time, every node applies it when "
                            "the bus is back; the scene version will say)",
                            s_->options.timeout_ms, kSettleLookMs / 1000)};
    return {0, 0, BusError::kUnavailable,
            fmt::format("the scene bus did not confirm the write within {} ms; it is refused "
                        "and stays refused (a copy the bus stores later is taken by no node)",
                        s_->options.timeout_ms)};
}

namespace {

kvWatcher* make_watcher(kvStore* kv) {
    kvWatcher* w = nullptr;
    kvWatchOptions wo;
    kvWatchOptions_Init(&wo);
    wo.IgnoreDeletes = true;
    return kvStore_Watch(&w, kv, kKey, &wo) == NATS_OK ? w : nullptr;
}

}  // namespace

void SceneBus::watch(std::function<void(const Value&)> on_scene) {
    on_scene_ = std::move(on_scene);
    // Made here, so that every write after watch() returns is delivered after the latest one.
    kvWatcher* first = make_watcher(s_->kv);
    thread_ = std::thread([this, first] { watch_loop(first); });
    check_thread_ = std::thread([this] { check_loop(); });
}

void SceneBus::pause_watch(bool paused) {
    watch_paused_ = paused;
    while (paused && !watch_parked_ && !stop_)
        std::this_thread::sleep_for(std::chrono::milliseconds(5));
}

void SceneBus::deliver(const Value& v) {
    std::lock_guard lock(deliver_mutex_);
    on_scene_(v);
}

void SceneBus::check_loop() {
    // Every 2 s the key is read (check_bus): a watch behind it twice in a row is made again (it
    // can stall without an error when its consumer lived on a server that died, or the bus was
    // frozen), a bus found empty or behind the held version is refilled, and values the watch
    // has not delivered are read directly. It runs in the seconds after a reconnect too, while
    // the watch waits to be made again: a bus that came back without its store gets the held
    // scene back at once, and a read that times out while the bus elects its leaders refills
    // nothing (refill() takes only a key the bus says is missing for an empty one).
    int behind = 0;
    uint64_t epoch = watch_epoch_.load();
    while (!stop_) {
        const auto next = std::chrono::steady_clock::now() + std::chrono::seconds(2);
        while (!stop_ && std::chrono::steady_clock::now() < next)
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
        if (const uint64_t e = watch_epoch_.load(); e != epoch) {
            epoch = e;  // a watch made since: it is counted behind from now
            behind = 0;
        }
        if (!stop_ && check_bus(behind)) {
            behind = 0;
            remake_ = true;
        }
    }
}

void SceneBus::watch_loop(void* first) {
    kvWatcher* w = static_cast<kvWatcher*>(first);
    // After a reconnect: when the watch is made again (never: not pending), and the latest
    // that may be.
    constexpr auto never = std::chrono::steady_clock::time_point::max();
    auto remake_at = never, remake_by = never;
    while (!stop_) {
        if (!w) {
            remake_ = false;  // a request made before this watcher is answered by it
            w = make_watcher(s_->kv);
            if (w)
                ++watch_epoch_;
        }
        if (!w) {
            // No watch (the bucket may be gone with a bus that restarted empty): the check
            // still runs on its own thread, and refills it.
            watch_parked_ = watch_paused_.load();
            std::this_thread::sleep_for(std::chrono::milliseconds(250));
            continue;
        }
        while (!stop_) {
            while (watch_paused_ && !stop_) {
                watch_parked_ = true;
                std::this_thread::sleep_for(std::chrono::milliseconds(10));
            }
            watch_parked_ = false;
            // A burst is taken whole (bounded), and only its newest signed value is
            // delivered: a flood costs one check per value and one scene at most.
            std::optional<Value> newest;
            natsStatus s = NATS_OK;
            uint64_t read = 0;  // the newest revision of the burst
            for (int taken = 0; taken < 4096; ++taken) {
                kvEntry* e = nullptr;
                s = kvWatcher_Next(&e, w, taken == 0 ? 200 : 1);
                if (s != NATS_OK)
                    break;
                if (!e)
                    continue;  // the end of the initial values
                auto v = check(kvEntry_Revision(e), kvEntry_Created(e),
                               std::string_view(static_cast<const char*>(kvEntry_Value(e)),
                                                size_t(kvEntry_ValueLen(e))));
                if (kvEntry_Revision(e) > watched_)  // this thread alone writes it
                    watched_ = kvEntry_Revision(e);
                read = std::max(read, kvEntry_Revision(e));
                kvEntry_Destroy(e);
                if (v) {
                    if (newest)
                        ++counters_.superseded_values;
                    keep_newest(newest, std::move(*v));
                }
            }
            if (newest)
                deliver(*newest);
            raise_to(delivered_, read);
            // After a reconnect the watch is made again, but only once the client has had a
            // second to reset its own consumers (destroying a watcher while the library resets
            // it is a race inside libnats): a second after the latest reconnect, and at most
            // three after the first. Until then nothing destroys the watcher, not an error
            // from it nor the check's request; the old watch is read meanwhile.
            const auto now = std::chrono::steady_clock::now();
            if (s_->reconnected.exchange(false)) {
                if (remake_at == never)
                    remake_by = now + std::chrono::seconds(3);
                remake_at = std::min(now + std::chrono::seconds(1), remake_by);
            }
            const bool failed = s != NATS_OK && s != NATS_TIMEOUT;
            if (remake_at != never && now < remake_at) {
                if (failed)  // it answers at once: not a busy loop
                    std::this_thread::sleep_for(std::chrono::milliseconds(50));
                continue;
            }
            if (remake_at != never || failed || remake_.exchange(false)) {
                remake_at = never;
                break;  // made again
            }
        }
        kvWatcher_Destroy(w);
        w = nullptr;
        watched_ = 0;  // the new watch has delivered nothing yet (a refill may have gone back)
    }
    if (w)
        kvWatcher_Destroy(w);
}

void SceneBus::hold(const Value& value) {
    std::lock_guard lock(held_mutex_);
    if (value.revision >= held_.revision)
        held_ = value;
}

SceneBus::Value SceneBus::held() const {
    std::lock_guard lock(held_mutex_);
    return held_;
}

void SceneBus::pass_over(const Value& v) {
    if (!v.refill)
        raise_to(passed_over_, v.revision);
}

std::optional<SceneBus::Refill> SceneBus::plan_refill(const Value& held, uint64_t bus_revision,
                                                      uint64_t last,
                                                      const std::optional<Value>& bus_newest) {
    if (held.revision == 0 || bus_revision >= held.revision)
        return std::nullopt;
    // A later admin's write on the bus (made after the held one, following a version): it goes
    // back, not the held one. A node's start-up scene on an empty bus follows none (base 0).
    if (bus_newest && !bus_newest->refill && bus_newest->base > 0 &&
        bus_newest->deadline_ms > held.deadline_ms)
        return Refill{std::max(held.revision + 1, last + 1), false};
    return Refill{std::max(held.revision, last + 1), true};
}

bool SceneBus::check_bus(int& behind) {
    uint64_t held, content;
    {
        std::lock_guard lock(held_mutex_);
        held = held_.revision;
        content = content_version(held_);
    }
    kvEntry* e = nullptr;
    const natsStatus s = kvStore_Get(&e, s_->kv, kKey);
    if (s == NATS_OK) {
        const uint64_t rev = kvEntry_Revision(e);
        const Top top = top_of(e, s_->options.admin_token, content);
        kvEntry_Destroy(e);
        // Behind the held version or a value passed over (which every node took as its
        // version), or one of those on top.
        const uint64_t passed = passed_over_.load();
        if (rev < std::max(held, passed) || top == Top::kStaleRefill ||
            (top == Top::kSigned && rev == passed))
            return refill();
        // Unsigned values that pushed every signed one out of the key's history (a flood of
        // more than it keeps): a node started now would find no scene to serve and put its own,
        // so the held one goes back on top (relabelled by every node, rebuilt by none).
        // The history changes only with a new value on top: read once per unsigned top.
        if (top == Top::kUnsigned && rev != unsigned_top_read_) {
            auto listed = read_signed(false);
            if (listed && listed->empty())
                return refill();
            if (listed)
                unsigned_top_read_ = rev;
        }
        // Values stored since the last one seen are read one by one and the newest delivered
        // now: a watch whose consumer lived on a server that died is only made again once the
        // bus's servers elect a new JetStream leader (seconds to tens of seconds on a loaded
        // machine), but a read needs only the stream's leader.
        if (rev > tail_.load())
            catch_up(rev);
        behind = rev > watched_ ? behind + 1 : 0;
        return behind >= 2;
    }
    // No value (deleted or purged), or no bucket at all (a bus that restarted without its
    // store answers a read of a missing stream with a timeout, so the stream is asked for).
    if (held > 0 && connected() && (s == NATS_NOT_FOUND || s == NATS_TIMEOUT))
        return refill();
    return false;
}

void SceneBus::keep_newest(std::optional<Value>& newest, Value v) {
    // The newest write: the greatest base (an old value put again has an old one), then the
    // first stored of that base (a later one is a copy put again; see read_signed).
    if (!newest || v.base > newest->base ||
        (v.base == newest->base && v.revision < newest->revision))
        newest = std::move(v);
}

void SceneBus::catch_up(uint64_t revision) {
    // From the newest delivered, not the newest seen: the watch may have read values it has
    // not delivered yet, and the newest write among them and the later ones goes first.
    const uint64_t from =
        std::max(delivered_.load() + 1, revision > kCatchUpMax ? revision - kCatchUpMax + 1 : 1);
    std::optional<Value> newest;
    uint64_t through = 0;  // the newest revision read
    for (uint64_t r = from; r <= revision && !stop_; ++r) {
        kvEntry* e = nullptr;
        const natsStatus got = kvStore_GetRevision(&e, s_->kv, kKey, r);
        if (got == NATS_NOT_FOUND) {
            through = r;
            continue;  // another key's, deleted, or purged
        }
        if (got != NATS_OK)
            break;  // the bus is slow or away: the next check tries again (no 256 timeouts)
        through = r;
        if (kvEntry_Operation(e) == kvOp_Put) {
            // Not counted here: a watch that runs again counts what it sees (a remade one sees
            // only the newest value, so ignored values of the gap may go uncounted).
            auto v = check(r, kvEntry_Created(e),
                           std::string_view(static_cast<const char*>(kvEntry_Value(e)),
                                            size_t(kvEntry_ValueLen(e))),
                           false);
            if (v)
                keep_newest(newest, std::move(*v));
        }
        kvEntry_Destroy(e);
    }
    if (newest) {
        ++counters_.caught_up;
        log::info("scene bus: the watch is behind the bus; version {} read directly",
                  newest->revision);
        deliver(*newest);
    }
    raise_to(delivered_, through);
}

bool SceneBus::refill() {
    Value held;
    {
        std::lock_guard lock(held_mutex_);
        held = held_;
    }
    // A value passed over raised every node's version to its revision: the held scene goes back
    // above it (as the same scene: its OF is kept), so that every node takes it.
    const uint64_t passed = passed_over_.load(), held_revision = held.revision;
    if (held.revision > 0 && passed >= held.revision) {
        if (!held.refill)
            held.of = held.revision;
        held.refill = true;
        held.revision = passed + 1;
    }
    const std::string stream = "KV_" + s_->options.bucket;
    jsStreamInfo* si = nullptr;
    jsErrCode jerr = jsErrCode(0);
    natsStatus s = js_GetStreamInfo(&si, s_->js, stream.c_str(), nullptr, &jerr);
    bool made = false;
    if (s == NATS_NOT_FOUND || jerr == JSStreamNotFoundErr) {
        kvStore* kv = nullptr;
        s = create_bucket(&kv, s_->js, s_->options);
        if (s != NATS_OK)
            return false;
        kvStore_Destroy(kv);
        made = true;
        s = js_GetStreamInfo(&si, s_->js, stream.c_str(), nullptr, &jerr);
    }
    if (s != NATS_OK || !si)
        return made;  // the bus is slow or frozen: nothing to say yet
    const uint64_t last = si->State.LastSeq;
    jsStreamInfo_Destroy(si);
    // What the bus holds now: its current revision (0: none) and its newest signed write.
    uint64_t bus_revision = 0;
    kvEntry* e = nullptr;
    Top top = Top::kSigned;
    // A read that fails says nothing about the key: only NOT_FOUND is an empty one. Taking a
    // timed-out read (a slow or frozen leader, an election) for an empty key would purge the
    // stream and put an older held version back over a newer acknowledged write.
    const natsStatus got = kvStore_Get(&e, s_->kv, kKey);
    if (got != NATS_OK && got != NATS_NOT_FOUND)
        return made;
    if (got == NATS_OK) {
        bus_revision = kvEntry_Revision(e);
        top = top_of(e, s_->options.admin_token, content_version(held));
        kvEntry_Destroy(e);
    }
    // Likewise the history: one that cannot be read is not one without a newer write.
    auto listed = read_signed(false);
    if (!listed)
        return made;
    // The key has a value and the stream (its leader) is at or past the held version: the read
    // that looked behind came from a follower of a replicated bucket that lags. Not behind,
    // unless that value is another node's refill of an older version, or is not signed and no
    // signed value is left in the history: then it is gone over.
    const bool over = top == Top::kStaleRefill || (top == Top::kUnsigned && listed->empty()) ||
                      (top == Top::kSigned && passed > 0 && bus_revision == passed);
    const uint64_t found = bus_revision;
    if (over)
        bus_revision = 0;
    else if (bus_revision != 0 && last >= held.revision)
        return made;
    // The newest signed write, of those this node did not pass over (one it passed over, or a
    // value coalesced before it, is not a scene to put back).
    std::optional<Value> newest;
    for (const auto& v : *listed)
        if (v.revision <= held_revision || v.revision > passed) {
            newest = v;
            break;
        }
    const auto plan = plan_refill(held, bus_revision, last, newest);
    if (!plan)
        return made;
    const Value& from = plan->ours ? held : *newest;
    // Every revision below the refill's goes (the bus's next sequence becomes its revision),
    // then it is written only if the key still has no value (another node's refill first makes
    // this one fail).
    jsOptions po;
    jsOptions_Init(&po);
    po.Stream.Purge.Sequence = plan->revision;
    if (const natsStatus p = js_PurgeStream(s_->js, stream.c_str(), &po, &jerr); p != NATS_OK) {
        log::warn("scene bus: found empty or behind (version {} held) but cannot purge it: {}",
                  held.revision, status_text(p));
        return made;
    }
    const uint64_t deadline = now_unix_ms() + uint64_t(s_->options.timeout_ms);
    // A held value puts back the version of its scene (a relabel keeps it); a newer write goes
    // back as the version it gets.
    const std::string value = sign(s_->options.admin_token, plan->revision - 1, deadline, from.json,
                                   plan->ours ? content_version(held) : plan->revision);
    uint64_t rev = 0;
    s = kvStore_Create(&rev, s_->kv, kKey, value.data(), int(value.size()));
    if (s != NATS_OK)
        return true;  // another node refilled it first: the watch is made again and takes it
    if (rev != plan->revision)
        log::warn(
            "scene bus: the refill landed at revision {}, not {} (another node purged or "
            "wrote meanwhile)",
            rev, plan->revision);
    signed_tail_ = rev;  // before tail_ (see check())
    tail_ = rev;  // lowered where the bus went back (a concurrent raise by the watch recovers)
    delivered_ = rev;
    ++counters_.refills;
    log::warn(
        "scene bus: the bus came back {} (revision {}, this node holds version {}): put "
        "{} back as version {}",
        top == Top::kStaleRefill      ? "with an older version put back by another node"
        : top == Top::kSigned && over ? "with a scene on top that this node cannot serve"
        : over              ? "with no signed value left (unsigned values pushed them out)"
        : bus_revision == 0 ? "empty"
                            : "behind",
        found, held_revision,
        plan->ours ? "the held scene" : fmt::format("the newer write of version {}", from.revision),
        rev);
    return true;
}

void SceneBus::heartbeat(const std::string& json) {
    const std::string subject = "node." + s_->options.node_id;
    (void)natsConnection_Publish(s_->nc, subject.c_str(), json.data(), int(json.size()));
}

}  // namespace hs::cluster
