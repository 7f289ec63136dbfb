#include "stream/loopback.hpp"

#include <algorithm>
#include <exception>
#include <mutex>
#include <random>
#include <thread>
#include <utility>

#include <fmt/format.h>

#include "core/log.hpp"
#include "stream/server.hpp"

namespace hs::stream {

struct LoopbackServer::Impl {
    std::unique_ptr<Server> server;
    std::string token;
    std::thread network;  // runs Server::run() until stop()
    std::mutex stopping;  // one stop() joins, a second waits for it
};

namespace {

// 128 random bits in hex: a token no other program on the machine guesses.
std::string random_token() {
    std::random_device rd;
    std::string t;
    for (int i = 0; i < 4; ++i) t += fmt::format("{:08x}", rd());
    return t;
}

ServerCreateInfo server_info(const LoopbackCreateInfo& o) {
    ServerCreateInfo info;
    info.host = "127.0.0.1";
    info.port = 0;
    info.token = o.token.empty() ? random_token() : o.token;
    info.asset_root = o.asset_root;
    info.limits.max_sessions = std::max(info.limits.max_sessions, o.clients + 8);
    info.limits.max_pending = std::max(info.limits.max_pending, o.clients + 8);
    if (o.max_batch_viewers > 0)
        info.limits.max_batch_viewers = o.max_batch_viewers;
    if (o.submissions_in_flight > 0)
        info.limits.submissions_in_flight = o.submissions_in_flight;
    if (o.max_target_mib > 0)
        info.limits.max_target_bytes = o.max_target_mib << 20;
    info.encoder_threads = o.encoder_threads;
    info.limits.headset_mbps = o.headset_mbps;
    info.limits.room_mbps = o.room_mbps;
    if (o.layer_quality > 0)
        info.layer_quality = o.layer_quality;
    info.renderer.planning_threads = o.planning_threads;
    info.renderer.record_on_planners = o.record_on_planners;
    info.renderer.pack_tiles = o.pack_tiles;
    info.renderer.multiview = o.multiview;
    info.renderer.headsets_per_pass = o.headsets_per_pass;
    info.renderer.max_layer_parts = o.max_layer_parts;
    info.calibration = o.calibration;
    return info;
}

}  // namespace

Result<std::unique_ptr<LoopbackServer>> LoopbackServer::start(gpu::Device& device,
                                                              const scene::Scene& scene,
                                                              const LoopbackCreateInfo& info) {
    const ServerCreateInfo server_create = server_info(info);
    HS_ASSIGN_OR_RETURN(auto server, Server::create(device, scene, server_create));
    auto impl = std::make_unique<Impl>();
    impl->server = std::move(server);
    impl->token = server_create.token;
    Server& s = *impl->server;
    impl->network = std::thread([&s] {
        try {
            s.run();
        } catch (const std::exception& e) {
            log::error("loopback server: the network loop stopped: {}", e.what());
        }
    });
    return std::unique_ptr<LoopbackServer>(new LoopbackServer(std::move(impl)));
}

LoopbackServer::LoopbackServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

LoopbackServer::~LoopbackServer() {
    stop();
}

uint16_t LoopbackServer::port() const {
    return impl_->server->port();
}

std::string LoopbackServer::address() const {
    return fmt::format("127.0.0.1:{}", port());
}

const std::string& LoopbackServer::token() const {
    return impl_->token;
}

Result<void> LoopbackServer::update_scene(const scene::Scene& scene) {
    return impl_->server->update_scene(scene);
}

nlohmann::json LoopbackServer::stats() const {
    return impl_->server->stats();
}

void LoopbackServer::stop() {
    std::lock_guard lock(impl_->stopping);
    if (!impl_->network.joinable())
        return;
    impl_->server->stop();
    impl_->network.join();
}

}  // namespace hs::stream
