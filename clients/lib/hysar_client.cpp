// The C API of libhysar-client (hysar_client.h) over hs::client::Session. Every entry point
// catches what C++ may throw and turns it into a status and a sentence.
#include "clients/lib/hysar_client.h"

#include <cmath>
#include <cstddef>
#include <cstring>
#include <mutex>
#include <new>
#include <string>
#include <unordered_set>
#include <vector>

#include "clients/common/common.hpp"
#include "clients/motion/motion.hpp"
#include "clients/session/session.hpp"

namespace proto = hs::protocol;
using hs::client::Session;
using hs::client::SessionConfig;
using hs::client::SessionEvent;

// A destination the library keeps: its pixels and where they may be lit
// (hysar_reproject_layer_into).
struct hysar_warp_target {
    uint32_t width = 0, height = 0, bytes_per_pixel = 4;
    std::vector<uint8_t> pixels;
    hs::motion::KeptRows kept;
};

struct hysar_client {
    std::unique_ptr<Session> session;
};

struct hysar_predictor {
    hs::motion::Predictor predictor;
};

static_assert(int(SessionEvent::Kind::kConnected) == HYSAR_EVENT_CONNECTED &&
              int(SessionEvent::Kind::kDisconnected) == HYSAR_EVENT_DISCONNECTED &&
              int(SessionEvent::Kind::kLayer) == HYSAR_EVENT_LAYER &&
              int(SessionEvent::Kind::kProjectorFrame) == HYSAR_EVENT_PROJECTOR_FRAME &&
              int(SessionEvent::Kind::kServerError) == HYSAR_EVENT_SERVER_ERROR &&
              int(SessionEvent::Kind::kStats) == HYSAR_EVENT_STATS &&
              int(SessionEvent::Kind::kClosed) == HYSAR_EVENT_CLOSED);
static_assert(int(proto::PixelFormat::kRgba8) == HYSAR_FORMAT_RGBA8 &&
              int(proto::PixelFormat::kRgba16f) == HYSAR_FORMAT_RGBA16F &&
              int(proto::Encoding::kRaw) == HYSAR_ENCODING_RAW &&
              int(proto::Encoding::kSparseTiles) == HYSAR_ENCODING_SPARSE &&
              int(proto::Encoding::kLossyTiles) == HYSAR_ENCODING_LOSSY &&
              int(proto::FrameMode::kContinuous) == HYSAR_MODE_CONTINUOUS);

namespace {

thread_local std::string t_error;

// The events hysar_client_poll handed out and hysar_event_release has not taken back: only
// those have an internal_ the library may look into. Never destroyed (a release may come from
// another static's destructor).
std::mutex& live_events_mutex() {
    static auto* m = new std::mutex;
    return *m;
}
std::unordered_set<const void*>& live_events() {
    static auto* s = new std::unordered_set<const void*>;
    return *s;
}

hysar_status fail(hysar_status s, std::string text) {
    t_error = std::move(text);
    return s;
}

// Runs `f` (returns hysar_status); exceptions become statuses.
template <typename F>
hysar_status guarded(F&& f) noexcept {
    try {
        t_error.clear();
        return f();
    } catch (const std::bad_alloc&) {
        return fail(HYSAR_E_NO_MEMORY, "out of memory");
    } catch (const std::exception& e) {
        return fail(HYSAR_E_INTERNAL, std::string("internal error: ") + e.what());
    } catch (...) {
        return fail(HYSAR_E_INTERNAL, "internal error");
    }
}

hysar_status from_session(const std::optional<Session::Refusal>& refusal) {
    if (!refusal)
        return HYSAR_OK;
    return fail(refusal->closed ? HYSAR_E_CLOSED : HYSAR_E_INVALID_ARGUMENT, refusal->text);
}

proto::Pose to_proto(const hysar_pose& p) {
    proto::Pose q;
    q.client_time_ns = p.time_ns;
    for (int i = 0; i < 3; ++i) q.position_m[i] = p.position_m[i];
    for (int i = 0; i < 4; ++i) q.orientation_wxyz[i] = p.orientation_wxyz[i];
    return q;
}

hysar_pose from_proto(const proto::Pose& q) {
    hysar_pose p{};
    p.time_ns = q.client_time_ns;
    for (int i = 0; i < 3; ++i) p.position_m[i] = q.position_m[i];
    for (int i = 0; i < 4; ++i) p.orientation_wxyz[i] = q.orientation_wxyz[i];
    return p;
}

// A C enum value as the protocol's enum, or nullopt outside [lo, hi].
template <typename E>
std::optional<E> enum_value(uint32_t v, uint32_t lo, uint32_t hi) {
    if (v < lo || v > hi)
        return std::nullopt;
    return E(v);
}

}  // namespace

extern "C" {

uint32_t hysar_client_api_version(void) {
    return HYSAR_CLIENT_API_VERSION;
}

const char* hysar_status_name(hysar_status s) {
    switch (s) {
        case HYSAR_OK:
            return "ok";
        case HYSAR_E_INVALID_ARGUMENT:
            return "invalid argument";
        case HYSAR_E_CONNECT:
            return "cannot connect";
        case HYSAR_E_REFUSED:
            return "refused by the server";
        case HYSAR_E_PROTOCOL:
            return "protocol error";
        case HYSAR_E_CLOSED:
            return "closed";
        case HYSAR_E_NO_MEMORY:
            return "out of memory";
        case HYSAR_E_INTERNAL:
            return "internal error";
    }
    return "unknown status";
}

const char* hysar_last_error(void) {
    return t_error.c_str();
}

uint64_t hysar_now_ns(void) {
    return hs::client::now_ns();
}

void hysar_client_config_init(hysar_client_config* c) {
    if (!c)
        return;
    *c = hysar_client_config{};
    c->struct_size = sizeof(hysar_client_config);
    c->role = HYSAR_ROLE_HMD;
    const SessionConfig d;
    c->connect_timeout_ms = uint32_t(d.connect_timeout_ms);
    c->reconnect_initial_ms = uint32_t(d.reconnect_initial_ms);
    c->reconnect_max_ms = uint32_t(d.reconnect_max_ms);
    c->reconnect_attempts = d.reconnect_attempts;
    c->keepalive_ms = uint32_t(d.keepalive_ms);
    c->queue_limit = uint32_t(d.queue_limit);
}

hysar_status hysar_display_from_profile(const char* path, double scale, hysar_display* out) {
    return guarded([&] {
        if (!path || !out)
            return fail(HYSAR_E_INVALID_ARGUMENT, "path and out must not be NULL");
        if (!std::isfinite(scale) || scale < 0.01 || scale > 8)
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        "scale " + std::to_string(scale) + " is outside [0.01, 8]");
        proto::RegisterDisplay d;
        if (auto err = hs::client::load_profile(path, scale, &d))
            return fail(HYSAR_E_INVALID_ARGUMENT, *err);
        *out = hysar_display{d.eye_width,
                             d.eye_height,
                             d.fx,
                             d.fy,
                             d.cx,
                             d.cy,
                             d.ipd_m,
                             HYSAR_FORMAT_RGBA8,
                             HYSAR_ENCODING_LOSSY,
                             HYSAR_MODE_CONTINUOUS};
        return HYSAR_OK;
    });
}

hysar_status hysar_client_connect(const hysar_client_config* c, hysar_client** out) {
    return guarded([&] {
        if (!c || !out)
            return fail(HYSAR_E_INVALID_ARGUMENT, "config and out must not be NULL");
        *out = nullptr;
        // A config from a newer header is longer; one from 1.0's ends at queue_limit (its TLS
        // fields are not read); anything shorter was not made by hysar_client_config_init.
        constexpr size_t kSize10 = offsetof(hysar_client_config, queue_limit) + sizeof(uint32_t);
        if (c->struct_size < kSize10)
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        "config.struct_size is " + std::to_string(c->struct_size) +
                            ", expected at least " + std::to_string(kSize10) +
                            " (call hysar_client_config_init first)");
        const bool has_tls = c->struct_size >= sizeof(hysar_client_config);
        if (!c->address || !c->token)
            return fail(HYSAR_E_INVALID_ARGUMENT, "config.address and config.token are required");
        SessionConfig sc;
        sc.address = c->address;
        sc.token = c->token;
        sc.name = c->name ? c->name : "hysar-client";
        sc.role = proto::Role(c->role);
        sc.connect_timeout_ms = int(std::min<uint32_t>(c->connect_timeout_ms, 1u << 30));
        sc.reconnect_initial_ms = int(std::min<uint32_t>(c->reconnect_initial_ms, 1u << 30));
        sc.reconnect_max_ms = int(std::min<uint32_t>(c->reconnect_max_ms, 1u << 30));
        sc.reconnect_attempts = c->reconnect_attempts;
        sc.keepalive_ms = int(std::min<uint32_t>(c->keepalive_ms, 1u << 30));
        sc.queue_limit = c->queue_limit;
        if (has_tls) {
            sc.tls.ca_file = c->tls_ca_file ? c->tls_ca_file : "";
            sc.tls.enabled = c->tls != 0 || c->tls_ca_file || c->tls_fingerprint;
            if (c->tls_fingerprint) {
                std::string why;
                auto f = hs::client::normalise_fingerprint(c->tls_fingerprint, &why);
                if (!f)
                    return fail(HYSAR_E_INVALID_ARGUMENT, "config.tls_fingerprint: " + why);
                sc.tls.fingerprint = *f;
            }
        }
        if (auto bad = hs::client::check_config(sc))
            return fail(HYSAR_E_INVALID_ARGUMENT, "config." + *bad);
        auto s = Session::connect(std::move(sc));
        if (auto* e = std::get_if<Session::ConnectError>(&s))
            return fail(e->refused ? HYSAR_E_REFUSED : HYSAR_E_CONNECT, e->text);
        *out = new hysar_client{std::move(std::get<std::unique_ptr<Session>>(s))};
        return HYSAR_OK;
    });
}

void hysar_client_close(hysar_client* client) {
    guarded([&] {
        delete client;
        return HYSAR_OK;
    });
}

hysar_status hysar_client_register_display(hysar_client* client, const hysar_display* d) {
    return hysar_client_register_display_opts(client, d, 0);
}

hysar_status hysar_client_register_display_opts(hysar_client* client, const hysar_display* d,
                                                uint32_t options) {
    return guarded([&] {
        if (options & ~uint32_t(HYSAR_OPTION_WARP_DEPTH))
            return fail(HYSAR_E_INVALID_ARGUMENT, "options " + std::to_string(options) +
                                                      " has bits other than "
                                                      "HYSAR_OPTION_WARP_DEPTH (1)");
        if (!client || !d)
            return fail(HYSAR_E_INVALID_ARGUMENT, "client and display must not be NULL");
        proto::RegisterDisplay r;
        r.eye_width = d->eye_width, r.eye_height = d->eye_height;
        r.fx = d->fx, r.fy = d->fy, r.cx = d->cx, r.cy = d->cy, r.ipd_m = d->ipd_m;
        auto format = enum_value<proto::PixelFormat>(d->format, 1, 2);
        auto encoding = enum_value<proto::Encoding>(d->encoding, 1, 3);
        auto mode = enum_value<proto::FrameMode>(d->mode, 0, 1);
        if (!format)
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        "display.format " + std::to_string(d->format) + " is not 1 or 2");
        if (!encoding)
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        "display.encoding " + std::to_string(d->encoding) + " is not 1, 2 or 3");
        if (!mode)
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        "display.mode " + std::to_string(d->mode) + " is not 0 or 1");
        r.format = *format, r.encoding = *encoding, r.mode = *mode;
        if (options & HYSAR_OPTION_WARP_DEPTH)
            r.options |= proto::kOptionWarpDepth;
        return from_session(client->session->register_display(r));
    });
}

hysar_status hysar_client_send_pose(hysar_client* client, const hysar_pose* pose,
                                    uint64_t* sent_time_ns) {
    return guarded([&] {
        if (!client || !pose)
            return fail(HYSAR_E_INVALID_ARGUMENT, "client and pose must not be NULL");
        proto::Pose p = to_proto(*pose);
        const hysar_status s = from_session(client->session->send_pose(p));
        if (s == HYSAR_OK && sent_time_ns)
            *sent_time_ns = p.client_time_ns;
        return s;
    });
}

hysar_status hysar_client_request_frame(hysar_client* client) {
    return guarded([&] {
        if (!client)
            return fail(HYSAR_E_INVALID_ARGUMENT, "client must not be NULL");
        return from_session(client->session->request_frame());
    });
}

hysar_status hysar_client_request_stats(hysar_client* client) {
    return guarded([&] {
        if (!client)
            return fail(HYSAR_E_INVALID_ARGUMENT, "client must not be NULL");
        return from_session(client->session->request_stats());
    });
}

hysar_status hysar_client_poll(hysar_client* client, int32_t timeout_ms, hysar_event* out) {
    return guarded([&] {
        if (!client || !out)
            return fail(HYSAR_E_INVALID_ARGUMENT, "client and out must not be NULL");
        *out = hysar_event{};
        out->text = "";
        if (client->session->closed())
            return fail(HYSAR_E_CLOSED, "the client is closed (the CLOSED event was taken)");
        auto e = client->session->poll(timeout_ms);
        if (!e)
            return HYSAR_OK;
        auto* held = new SessionEvent(std::move(*e));
        out->kind = uint32_t(held->kind);
        out->eye = held->eye;
        out->frame_id = held->frame_id;
        out->scene_version = held->scene_version;
        out->session_id = held->session_id;
        out->error_code = held->error_code;
        out->reconnects = held->reconnects;
        out->pose = from_proto(held->pose);
        out->received_ns = held->received_ns;
        out->decoded_ns = held->decoded_ns;
        if (!held->pixels.empty()) {
            const uint32_t bpp = held->format == proto::PixelFormat::kRgba8 ? 4 : 8;
            out->image = hysar_image{held->width, held->height,        uint32_t(held->format),
                                     bpp,         held->pixels.size(), held->pixels.data()};
        }
        out->text = held->text.c_str();
        out->internal_ = held;
        {
            std::lock_guard lock(live_events_mutex());
            live_events().insert(held);
        }
        return HYSAR_OK;
    });
}

void hysar_event_release(hysar_event* event) {
    if (!event)
        return;
    {
        std::lock_guard lock(live_events_mutex());
        live_events().erase(event->internal_);
    }
    delete static_cast<SessionEvent*>(event->internal_);
    *event = hysar_event{};
    event->text = "";
}

hysar_status hysar_client_get_info(hysar_client* client, hysar_client_info* out) {
    return guarded([&] {
        if (!client || !out)
            return fail(HYSAR_E_INVALID_ARGUMENT, "client and out must not be NULL");
        const auto i = client->session->info();
        *out = hysar_client_info{i.connected ? 1u : 0u, i.session_id,     i.scene_version,
                                 i.reconnects,          i.images_dropped, i.bytes_received};
        return HYSAR_OK;
    });
}

hysar_status hysar_client_get_clock(hysar_client* client, hysar_clock* out) {
    return guarded([&] {
        if (!client || !out)
            return fail(HYSAR_E_INVALID_ARGUMENT, "client and out must not be NULL");
        const auto c = client->session->clock();
        *out = hysar_clock{c.samples, 0, c.offset_ns, c.round_trip_ns, c.pose_to_layer_ns};
        return HYSAR_OK;
    });
}

hysar_status hysar_client_send_pose_at(hysar_client* client, const hysar_pose* pose,
                                       uint64_t display_time_ns, uint64_t* sent_time_ns) {
    return guarded([&] {
        if (!client || !pose)
            return fail(HYSAR_E_INVALID_ARGUMENT, "client and pose must not be NULL");
        proto::Pose p = to_proto(*pose);
        p.display_time_ns = display_time_ns;
        const hysar_status s = from_session(client->session->send_pose(p));
        if (s == HYSAR_OK && sent_time_ns)
            *sent_time_ns = p.client_time_ns;
        return s;
    });
}

double hysar_event_warp_depth_m(const hysar_event* event) {
    if (!event || event->kind != HYSAR_EVENT_LAYER || !event->internal_)
        return 0;
    std::lock_guard live_lock(live_events_mutex());
    if (!live_events().count(event->internal_))
        return 0;
    return static_cast<const SessionEvent*>(event->internal_)->warp_depth_m;
}

uint64_t hysar_event_display_time_ns(const hysar_event* event) {
    if (!event || event->kind != HYSAR_EVENT_LAYER || !event->internal_)
        return 0;
    return static_cast<const SessionEvent*>(event->internal_)->pose.display_time_ns;
}

void hysar_predictor_config_init(hysar_predictor_config* config) {
    if (!config)
        return;
    const hs::motion::PredictorConfig d;
    *config = hysar_predictor_config{sizeof(hysar_predictor_config),
                                     0,
                                     d.window_ms,
                                     d.filter_ms,
                                     d.max_horizon_ms,
                                     d.max_angle_deg,
                                     d.max_distance_m,
                                     d.smooth_ms};
}

hysar_status hysar_predictor_create(const hysar_predictor_config* config, hysar_predictor** out) {
    return guarded([&] {
        if (!out)
            return fail(HYSAR_E_INVALID_ARGUMENT, "out must not be NULL");
        *out = nullptr;
        hs::motion::PredictorConfig c;
        if (config) {
            // API 2's struct ends before smooth_ms.
            constexpr uint32_t kSize2 = offsetof(hysar_predictor_config, smooth_ms);
            if (config->struct_size != sizeof(hysar_predictor_config) &&
                config->struct_size != kSize2)
                return fail(HYSAR_E_INVALID_ARGUMENT,
                            "predictor config struct_size " + std::to_string(config->struct_size) +
                                " is not " + std::to_string(sizeof(hysar_predictor_config)) +
                                " (or " + std::to_string(kSize2) +
                                " before smooth_ms; call hysar_predictor_config_init)");
            c.window_ms = config->window_ms, c.filter_ms = config->filter_ms;
            c.max_horizon_ms = config->max_horizon_ms, c.max_angle_deg = config->max_angle_deg;
            c.max_distance_m = config->max_distance_m;
            if (config->struct_size == sizeof(hysar_predictor_config))
                c.smooth_ms = config->smooth_ms;
        }
        if (auto bad = hs::motion::check(c))
            return fail(HYSAR_E_INVALID_ARGUMENT, *bad);
        *out = new hysar_predictor{hs::motion::Predictor(c)};
        return HYSAR_OK;
    });
}

void hysar_predictor_destroy(hysar_predictor* predictor) {
    delete predictor;
}

hysar_status hysar_predictor_add_with_velocity(hysar_predictor* predictor, const hysar_pose* sample,
                                               const double angular_velocity[3],
                                               const double linear_velocity[3]) {
    return guarded([&] {
        if (!predictor || !sample)
            return fail(HYSAR_E_INVALID_ARGUMENT, "predictor and sample must not be NULL");
        if (!angular_velocity != !linear_velocity)
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        std::string(angular_velocity ? "linear_velocity" : "angular_velocity") +
                            " is NULL: give both velocities, or neither");
        hs::motion::PoseSample s;
        s.time_ns = sample->time_ns;
        for (size_t i = 0; i < 3; ++i) s.position_m[i] = sample->position_m[i];
        for (size_t i = 0; i < 4; ++i) s.orientation_wxyz[i] = sample->orientation_wxyz[i];
        if (angular_velocity) {
            s.has_velocity = true;
            for (size_t i = 0; i < 3; ++i)
                s.angular_velocity[i] = angular_velocity[i],
                s.linear_velocity[i] = linear_velocity[i];
        }
        if (!predictor->predictor.add(s))
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        std::string("pose sample refused: a non-finite number") +
                            (s.has_velocity ? " (velocities included)" : "") +
                            ", a zero quaternion, or a time_ns not after the newest sample's");
        return HYSAR_OK;
    });
}

hysar_status hysar_predictor_add(hysar_predictor* predictor, const hysar_pose* sample) {
    return hysar_predictor_add_with_velocity(predictor, sample, nullptr, nullptr);
}

hysar_status hysar_predictor_predict(const hysar_predictor* predictor, uint64_t display_time_ns,
                                     hysar_pose* out) {
    return guarded([&] {
        if (!predictor || !out)
            return fail(HYSAR_E_INVALID_ARGUMENT, "predictor and out must not be NULL");
        const auto p = predictor->predictor.predict(display_time_ns);
        if (!p)
            return fail(HYSAR_E_INVALID_ARGUMENT, "the predictor has no sample yet");
        const auto newest = predictor->predictor.predict(0);
        out->time_ns = newest->time_ns;
        for (size_t i = 0; i < 3; ++i) out->position_m[i] = p->position_m[i];
        for (size_t i = 0; i < 4; ++i) out->orientation_wxyz[i] = p->orientation_wxyz[i];
        return HYSAR_OK;
    });
}

uint64_t hysar_next_display_time_ns(uint64_t earliest_ns, double refresh_hz, uint64_t vsync_ns) {
    return hs::motion::next_display_time_ns(earliest_ns, refresh_hz, vsync_ns);
}

}  // extern "C"

namespace {

// Both reprojection entry points: `rendered` is the display the layer was rendered for, `shown`
// the one dst is for (the same display unless the session registered an overscanned one).
hysar_status reproject(const hysar_event* layer, const hysar_display* rendered,
                       const hysar_display* shown, uint32_t dst_width, uint32_t dst_height,
                       const hysar_pose* latest, uint64_t now_ns, uint64_t stale_limit_ns,
                       double plane_depth_m, uint32_t filter, uint8_t* dst, size_t dst_bytes,
                       uint32_t* cleared, hs::motion::KeptRows* kept = nullptr) {
    const hysar_image& im = layer->image;
    // The image's own fields must agree: the warp reads width x height x bpp (sizes bounded
    // first, so that the product cannot wrap).
    if (im.width == 0 || im.height == 0 || im.width > 16384 || im.height > 16384)
        return fail(HYSAR_E_INVALID_ARGUMENT, "the image is " + std::to_string(im.width) + "x" +
                                                  std::to_string(im.height) +
                                                  ", not within 1..16384 on each side");
    if (im.bytes_per_pixel != 4 && im.bytes_per_pixel != 8)
        return fail(HYSAR_E_INVALID_ARGUMENT, "the image's bytes_per_pixel is " +
                                                  std::to_string(im.bytes_per_pixel) +
                                                  ", not 4 (rgba8) or 8 (rgba16f)");
    if (uint64_t(im.width) * im.height * im.bytes_per_pixel != uint64_t(im.size_bytes))
        return fail(HYSAR_E_INVALID_ARGUMENT,
                    "the image's size_bytes " + std::to_string(im.size_bytes) +
                        " is not width x height x bytes_per_pixel (" + std::to_string(im.width) +
                        " x " + std::to_string(im.height) + " x " +
                        std::to_string(im.bytes_per_pixel) + ")");
    const uint64_t dst_needed = uint64_t(dst_width) * dst_height * im.bytes_per_pixel;
    if (dst_bytes < dst_needed)
        return fail(HYSAR_E_INVALID_ARGUMENT, "dst_bytes " + std::to_string(dst_bytes) +
                                                  " is less than the " +
                                                  std::to_string(dst_needed) + " shown");
    if (filter > HYSAR_FILTER_BILINEAR)
        return fail(HYSAR_E_INVALID_ARGUMENT,
                    "filter " + std::to_string(filter) + " is not 0 (nearest) or 1 (bilinear)");
    for (const hysar_display* d : {rendered, shown})
        if (!(d->fx > 0 && d->fy > 0 && std::isfinite(d->fx) && std::isfinite(d->fy) &&
              std::isfinite(d->cx) && std::isfinite(d->cy)))
            return fail(HYSAR_E_INVALID_ARGUMENT, "display intrinsics must be finite, fx, fy > 0");
    if (plane_depth_m != HYSAR_PLANE_DEPTH_FROM_LAYER &&
        (!(plane_depth_m >= 0) || !std::isfinite(plane_depth_m)))
        return fail(HYSAR_E_INVALID_ARGUMENT, "plane_depth_m " + std::to_string(plane_depth_m) +
                                                  " must be finite and >= 0 (0: rotation only), or "
                                                  "HYSAR_PLANE_DEPTH_FROM_LAYER");
    hs::motion::Quat render, now;
    hs::motion::Vec3 render_at, now_at;
    for (size_t i = 0; i < 4; ++i) {
        render[i] = layer->pose.orientation_wxyz[i];
        now[i] = latest->orientation_wxyz[i];
    }
    for (size_t i = 0; i < 3; ++i) {
        render_at[i] = layer->pose.position_m[i];
        now_at[i] = latest->position_m[i];
    }
    for (size_t i = 0; i < 4; ++i)
        if (!std::isfinite(now[i]) || !std::isfinite(render[i]))
            return fail(HYSAR_E_INVALID_ARGUMENT, "a pose's quaternion is not finite");
    for (size_t i = 0; i < 3; ++i)
        if (!std::isfinite(now_at[i]) || !std::isfinite(render_at[i]))
            return fail(HYSAR_E_INVALID_ARGUMENT, "a pose's position is not finite");
    const auto n2 = [](const hs::motion::Quat& q) {
        return q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
    };
    if (!(n2(render) > 1e-12) || !(n2(now) > 1e-12))
        return fail(HYSAR_E_INVALID_ARGUMENT, "a pose's quaternion is zero");
    const bool stale = stale_limit_ns != 0 && now_ns > layer->pose.time_ns &&
                       now_ns - layer->pose.time_ns > stale_limit_ns;
    if (cleared)
        *cleared = stale ? 1 : 0;
    if (stale) {
        if (kept)
            hs::motion::clear_kept(dst, dst_width, dst_height, im.bytes_per_pixel, *kept);
        else
            std::memset(dst, 0, size_t(dst_needed));
        return HYSAR_OK;
    }
    // A layer the library decoded knows where it may be lit (its tiles): the warp need not
    // scan it. Only if the event's image is still the library's own.
    // internal_ is looked at only if the library handed it out and it was not released since
    // (a caller may build or copy an event itself).
    // The rows are copied (a few kB): another thread may release the event meanwhile.
    hs::motion::LitRows lit;
    thread_local std::vector<uint32_t> lit_first, lit_last;
    {
        std::lock_guard live_lock(live_events_mutex());
        if (live_events().count(layer->internal_)) {
            const auto* held = static_cast<const SessionEvent*>(layer->internal_);
            if (plane_depth_m == HYSAR_PLANE_DEPTH_FROM_LAYER && held->eye == layer->eye &&
                held->frame_id == layer->frame_id)
                plane_depth_m = held->warp_depth_m;
            if (held->pixels.data() == im.pixels && held->width == im.width &&
                held->height == im.height && held->lit_first.size() == im.height &&
                held->lit_last.size() == im.height) {
                lit_first = held->lit_first, lit_last = held->lit_last;
                lit = {lit_first.data(), lit_last.data()};
            }
        }
    }
    if (plane_depth_m == HYSAR_PLANE_DEPTH_FROM_LAYER)
        plane_depth_m = 0;  // not a layer the library holds: rotation only
    const hs::motion::Pinhole kr{rendered->fx, rendered->fy, rendered->cx, rendered->cy};
    const hs::motion::Pinhole kd{shown->fx, shown->fy, shown->cx, shown->cy};
    const int eye = layer->eye == 1 ? 1 : 0;
    const double ipd = std::isfinite(shown->ipd_m) ? shown->ipd_m : 0;
    hs::motion::warp(
        im.pixels, im.width, im.height, dst, dst_width, dst_height, im.bytes_per_pixel,
        hs::motion::plane_homography(kr, kd, hs::motion::eye_pose(render_at, render, ipd, eye),
                                     hs::motion::eye_pose(now_at, now, ipd, eye), plane_depth_m),
        filter == HYSAR_FILTER_BILINEAR ? hs::motion::Filter::kBilinear
                                        : hs::motion::Filter::kNearest,
        lit, kept);
    return HYSAR_OK;
}

// The checks hysar_reproject_layer_to and hysar_reproject_layer_into share; HYSAR_OK when the
// arguments can be warped.
hysar_status check_reproject_to(const hysar_event* layer, const hysar_display* rendered,
                                const hysar_display* shown, const hysar_pose* latest) {
    if (!layer || !rendered || !shown || !latest)
        return fail(HYSAR_E_INVALID_ARGUMENT,
                    "layer, rendered, shown, latest and the destination must not be NULL");
    if (layer->kind != HYSAR_EVENT_LAYER || !layer->image.pixels)
        return fail(HYSAR_E_INVALID_ARGUMENT, "the event is not a LAYER with an image");
    if (layer->image.width != rendered->eye_width || layer->image.height != rendered->eye_height)
        return fail(HYSAR_E_INVALID_ARGUMENT, "the layer is " + std::to_string(layer->image.width) +
                                                  "x" + std::to_string(layer->image.height) +
                                                  ", not the rendered display's " +
                                                  std::to_string(rendered->eye_width) + "x" +
                                                  std::to_string(rendered->eye_height));
    if (shown->eye_width == 0 || shown->eye_height == 0 || shown->eye_width > 8192 ||
        shown->eye_height > 8192)
        return fail(HYSAR_E_INVALID_ARGUMENT,
                    "the shown display is " + std::to_string(shown->eye_width) + "x" +
                        std::to_string(shown->eye_height) + ", not within 1..8192");
    return HYSAR_OK;
}

}  // namespace

extern "C" {

hysar_status hysar_reproject_layer(const hysar_event* layer, const hysar_display* display,
                                   const hysar_pose* latest, uint64_t now_ns,
                                   uint64_t stale_limit_ns, double plane_depth_m, uint32_t filter,
                                   uint8_t* dst, size_t dst_bytes, uint32_t* cleared) {
    return guarded([&] {
        if (!layer || !display || !latest || !dst)
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        "layer, display, latest and dst must not be NULL");
        if (layer->kind != HYSAR_EVENT_LAYER || !layer->image.pixels)
            return fail(HYSAR_E_INVALID_ARGUMENT, "the event is not a LAYER with an image");
        return reproject(layer, display, display, layer->image.width, layer->image.height, latest,
                         now_ns, stale_limit_ns, plane_depth_m, filter, dst, dst_bytes, cleared);
    });
}

hysar_status hysar_reproject_layer_to(const hysar_event* layer, const hysar_display* rendered,
                                      const hysar_display* shown, const hysar_pose* latest,
                                      uint64_t now_ns, uint64_t stale_limit_ns,
                                      double plane_depth_m, uint32_t filter, uint8_t* dst,
                                      size_t dst_bytes, uint32_t* cleared) {
    return guarded([&] {
        if (!dst)
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        "layer, rendered, shown, latest and dst must not be NULL");
        if (const hysar_status s = check_reproject_to(layer, rendered, shown, latest); s)
            return s;
        return reproject(layer, rendered, shown, shown->eye_width, shown->eye_height, latest,
                         now_ns, stale_limit_ns, plane_depth_m, filter, dst, dst_bytes, cleared);
    });
}

hysar_status hysar_warp_target_create(uint32_t width, uint32_t height, uint32_t bytes_per_pixel,
                                      hysar_warp_target** out) {
    return guarded([&] {
        if (!out)
            return fail(HYSAR_E_INVALID_ARGUMENT, "out must not be NULL");
        *out = nullptr;
        if (width == 0 || height == 0 || width > 8192 || height > 8192)
            return fail(HYSAR_E_INVALID_ARGUMENT, "a warp target of " + std::to_string(width) +
                                                      "x" + std::to_string(height) +
                                                      " is not within 1..8192 on each side");
        if (bytes_per_pixel != 4 && bytes_per_pixel != 8)
            return fail(HYSAR_E_INVALID_ARGUMENT, "bytes_per_pixel " +
                                                      std::to_string(bytes_per_pixel) +
                                                      " is not 4 (rgba8) or 8 (rgba16f)");
        auto t = std::make_unique<hysar_warp_target>();
        t->width = width, t->height = height, t->bytes_per_pixel = bytes_per_pixel;
        t->pixels.assign(size_t(width) * height * bytes_per_pixel, 0);
        t->kept.first.assign(height, 0);  // all 0, and known to be
        t->kept.last.assign(height, 0);
        t->kept.width = width, t->kept.bytes_per_pixel = bytes_per_pixel;
        *out = t.release();
        return HYSAR_OK;
    });
}

void hysar_warp_target_destroy(hysar_warp_target* target) {
    delete target;
}

const uint8_t* hysar_warp_target_pixels(const hysar_warp_target* target) {
    return target ? target->pixels.data() : nullptr;
}

hysar_status hysar_reproject_layer_into(const hysar_event* layer, const hysar_display* rendered,
                                        const hysar_display* shown, const hysar_pose* latest,
                                        uint64_t now_ns, uint64_t stale_limit_ns,
                                        double plane_depth_m, uint32_t filter,
                                        hysar_warp_target* target, uint32_t* cleared) {
    return guarded([&] {
        if (!target)
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        "layer, rendered, shown, latest and target must not be NULL");
        if (const hysar_status s = check_reproject_to(layer, rendered, shown, latest); s)
            return s;
        if (layer->image.bytes_per_pixel != 4 && layer->image.bytes_per_pixel != 8)
            return fail(HYSAR_E_INVALID_ARGUMENT, "the image's bytes_per_pixel is " +
                                                      std::to_string(layer->image.bytes_per_pixel) +
                                                      ", not 4 (rgba8) or 8 (rgba16f)");
        if (target->width != shown->eye_width || target->height != shown->eye_height ||
            target->bytes_per_pixel != layer->image.bytes_per_pixel)
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        "the target is " + std::to_string(target->width) + "x" +
                            std::to_string(target->height) + " at " +
                            std::to_string(target->bytes_per_pixel) +
                            " bytes a pixel, not the shown display's " +
                            std::to_string(shown->eye_width) + "x" +
                            std::to_string(shown->eye_height) + " at the layer's " +
                            std::to_string(layer->image.bytes_per_pixel));
        return reproject(layer, rendered, shown, shown->eye_width, shown->eye_height, latest,
                         now_ns, stale_limit_ns, plane_depth_m, filter, target->pixels.data(),
                         target->pixels.size(), cleared, &target->kept);
    });
}

hysar_status hysar_display_overscan(const hysar_display* display, double margin_deg,
                                    hysar_display* out) {
    return guarded([&] {
        if (!display || !out)
            return fail(HYSAR_E_INVALID_ARGUMENT, "display and out must not be NULL");
        if (!(margin_deg >= 0 && margin_deg <= hs::motion::kMaxOverscanDeg))
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        "margin_deg " + std::to_string(margin_deg) + " is outside [0, 30]");
        const auto o = hs::motion::overscan({display->fx, display->fy, display->cx, display->cy},
                                            display->eye_width, display->eye_height, margin_deg);
        if (!o)
            return fail(HYSAR_E_INVALID_ARGUMENT,
                        "the display cannot be widened by " + std::to_string(margin_deg) +
                            " degrees: its size must be 1..8192, its intrinsics finite with fx, "
                            "fy > 0, and the widened display within 8192 pixels and 90 degrees");
        hysar_display d = *display;
        d.eye_width = o->width, d.eye_height = o->height;
        d.cx = o->k.cx, d.cy = o->k.cy;
        *out = d;
        return HYSAR_OK;
    });
}

}  // extern "C"
