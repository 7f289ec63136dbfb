#include "cluster/scene_bus.hpp"

#include <nats/nats.h>

#include <chrono>

#include <fmt/format.h>

#include "core/log.hpp"

namespace hs::cluster {

namespace {

constexpr const char* kKey = "scene";

std::string status_text(natsStatus s) {
    const char* last = nats_GetLastError(nullptr);
    return last && *last ? last : natsStatus_GetText(s);
}

}  // namespace

std::string conflict_message(uint64_t current_revision) {
    return fmt::format("scene changed concurrently, now version {}; fetch it and try again",
                       current_revision);
}

struct SceneBus::State {
    Options options;
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
}

Result<std::unique_ptr<SceneBus>> SceneBus::connect(const Options& o) {
    auto st = std::make_unique<State>();
    st->options = o;
    natsOptions* opts = nullptr;
    natsStatus s = natsOptions_Create(&opts);
    if (s == NATS_OK)
        s = natsOptions_SetURL(opts, o.url.c_str());
    if (s == NATS_OK)
        s = natsOptions_SetTimeout(opts, o.timeout_ms);
    if (s == NATS_OK)
        s = natsOptions_SetMaxReconnect(opts, -1);  // forever: nodes outlive a bus outage
    if (s == NATS_OK)
        s = natsOptions_SetReconnectWait(opts, 250);
    if (s == NATS_OK)
        s = natsConnection_Connect(&st->nc, opts);
    if (opts)
        natsOptions_Destroy(opts);
    if (s != NATS_OK)
        return make_error(ErrorCode::kIo, fmt::format("--cluster {}: cannot connect to the scene "
                                                      "bus: {}",
                                                      o.url, status_text(s)));
    jsOptions jo;
    jsOptions_Init(&jo);
    jo.Wait = o.timeout_ms;
    s = natsConnection_JetStream(&st->js, st->nc, &jo);
    if (s == NATS_OK) {
        s = js_KeyValue(&st->kv, st->js, o.bucket.c_str());
        if (s == NATS_NOT_FOUND) {
            kvConfig cfg;
            kvConfig_Init(&cfg);
            cfg.Bucket = o.bucket.c_str();
            cfg.History = 1;
            cfg.MaxValueSize = 1 << 20;  // a SceneUpdate's limit
            s = js_CreateKeyValue(&st->kv, st->js, &cfg);
        }
    }
    if (s != NATS_OK)
        return make_error(ErrorCode::kIo,
                          fmt::format("--cluster {}: cannot open the key-value bucket '{}' "
                                      "(is JetStream on? nats-server -js): {}",
                                      o.url, o.bucket, status_text(s)));
    return std::unique_ptr<SceneBus>(new SceneBus(std::move(st)));
}

bool SceneBus::connected() const {
    return natsConnection_Status(s_->nc) == NATS_CONN_STATUS_CONNECTED;
}

Result<std::pair<uint64_t, std::string>> SceneBus::current() {
    kvEntry* e = nullptr;
    const natsStatus s = kvStore_Get(&e, s_->kv, kKey);
    if (s == NATS_NOT_FOUND)
        return std::pair<uint64_t, std::string>{0, ""};
    if (s != NATS_OK)
        return make_error(ErrorCode::kIo, "the scene bus: " + status_text(s));
    std::pair<uint64_t, std::string> out{
        kvEntry_Revision(e),
        std::string(static_cast<const char*>(kvEntry_Value(e)), size_t(kvEntry_ValueLen(e)))};
    kvEntry_Destroy(e);
    return out;
}

BusWrite SceneBus::write(uint64_t applied, const std::string& json) {
    // While disconnected the client would buffer the write and send it after the reconnect,
    // long after the admin was told it failed: refuse it here instead.
    if (!connected())
        return {0, BusError::kUnavailable,
                "the scene bus is unavailable (not connected to " + s_->options.url +
                    "); the running scene stays"};
    uint64_t rev = 0;
    const natsStatus s =
        applied == 0 ? kvStore_Create(&rev, s_->kv, kKey, json.data(), int(json.size()))
                     : kvStore_Update(&rev, s_->kv, kKey, json.data(), int(json.size()), applied);
    if (s == NATS_OK)
        return {rev, BusError::kNone, ""};
    const std::string why = status_text(s);
    if (why.find("wrong last sequence") != std::string::npos ||
        why.find("key exists") != std::string::npos) {
        auto now = current();
        return {0, BusError::kConflict, conflict_message(now.ok() ? now->first : applied + 1)};
    }
    if (s == NATS_TIMEOUT)
        return {0, BusError::kUnavailable,
                fmt::format("the scene bus did not confirm the write within {} ms; it may still "
                            "arrive (hysar admin stats shows the version)",
                            s_->options.timeout_ms)};
    return {0, BusError::kUnavailable,
            "the scene bus is unavailable (" + why + "); the running scene stays"};
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

void SceneBus::watch(std::function<void(uint64_t, const std::string&)> on_scene) {
    on_scene_ = std::move(on_scene);
    // Made here, so that every write after watch() returns is delivered after the latest one.
    kvWatcher* first = make_watcher(s_->kv);
    thread_ = std::thread([this, first] { watch_loop(first); });
}

void SceneBus::watch_loop(void* first) {
    kvWatcher* w = static_cast<kvWatcher*>(first);
    while (!stop_) {
        if (!w)
            w = make_watcher(s_->kv);
        if (!w) {
            std::this_thread::sleep_for(std::chrono::milliseconds(250));
            continue;
        }
        while (!stop_) {
            kvEntry* e = nullptr;
            const natsStatus s = kvWatcher_Next(&e, w, 200);
            if (s == NATS_TIMEOUT)
                continue;
            if (s != NATS_OK)
                break;  // made again
            if (!e)
                continue;  // the end of the initial values
            on_scene_(kvEntry_Revision(e), std::string(static_cast<const char*>(kvEntry_Value(e)),
                                                       size_t(kvEntry_ValueLen(e))));
            kvEntry_Destroy(e);
        }
        kvWatcher_Destroy(w);
        w = nullptr;
    }
    if (w)
        kvWatcher_Destroy(w);
}

void SceneBus::heartbeat(const std::string& json) {
    const std::string subject = "node." + s_->options.node_id;
    (void)natsConnection_Publish(s_->nc, subject.c_str(), json.data(), int(json.size()));
}

}  // namespace hs::cluster
