/* hysar_client.h: libhysar-client, the C API of a HySAR client (a headset or a projector).
 *
 * It connects to `hysar serve`, authenticates, registers a display, sends poses and hands back
 * decoded layers and projector frames with their pose, sequence and timing. When the server goes
 * away it reconnects by itself, with jittered exponential back-off, and sends Hello, the
 * registered display, the last pose and an unanswered frame request again; the application sees
 * DISCONNECTED and CONNECTED events and carries on.
 *
 * Threads: every function may be called from any thread (a warp target, one thread at a time);
 * one thread inside the library does the network. Nothing here throws or aborts: every function
 * returns a hysar_status, and hysar_last_error() gives the sentence of the last failure on the
 * calling thread.
 *
 * Ownership: the library copies every string and struct it is given. An event's pixels and
 * text belong to the event until hysar_event_release().
 *
 * Link with `pkg-config --cflags --libs hysar-client`. The wire protocol is protocol/PROTOCOL.md;
 * a 100-line example is examples/c/hmd_example.c.
 */
#ifndef HYSAR_CLIENT_H
#define HYSAR_CLIENT_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#if defined(__GNUC__)
#define HYSAR_API __attribute__((visibility("default")))
#else
#define HYSAR_API
#endif

/* The version of this API; hysar_client_api_version() returns the library's. */
#define HYSAR_CLIENT_API_VERSION 6

typedef enum hysar_status {
    HYSAR_OK = 0,
    HYSAR_E_INVALID_ARGUMENT = 1, /* a NULL pointer, a malformed address, a value out of range */
    HYSAR_E_CONNECT = 2,          /* the server cannot be reached */
    HYSAR_E_REFUSED = 3,          /* the server refused the session (a wrong token, ...) */
    HYSAR_E_PROTOCOL = 4,         /* reserved: a peer that is not HySAR is HYSAR_E_CONNECT today */
    HYSAR_E_CLOSED = 5,           /* the client was closed, or gave up reconnecting */
    HYSAR_E_NO_MEMORY = 6,
    HYSAR_E_INTERNAL = 7
} hysar_status;

enum { HYSAR_ROLE_PROJECTOR = 1, HYSAR_ROLE_HMD = 2 };
/* RGBA8: sRGB-encoded bytes. RGBA16F: linear radiance as IEEE 754 half floats. */
enum { HYSAR_FORMAT_RGBA8 = 1, HYSAR_FORMAT_RGBA16F = 2 };
/* What travels on the wire; the library hands back decoded pixels either way. LOSSY: sparse
 * tiles whose RGBA8 colour is JPEG-coded at the server's quality (black stays exactly black;
 * about a sixth of SPARSE's bytes); RGBA16F layers stay lossless. */
enum { HYSAR_ENCODING_RAW = 1, HYSAR_ENCODING_SPARSE = 2, HYSAR_ENCODING_LOSSY = 3 };
/* ON_REQUEST: one layer pair per hysar_client_request_frame(). CONTINUOUS: one per new pose,
 * the newest pose winning when the server is busy. */
enum { HYSAR_MODE_ON_REQUEST = 0, HYSAR_MODE_CONTINUOUS = 1 };

typedef struct hysar_client hysar_client;

typedef struct hysar_client_config {
    uint32_t struct_size;          /* sizeof(hysar_client_config) */
    const char* address;           /* "HOST:PORT", "[IPv6]:PORT" or "unix:PATH" */
    const char* token;             /* the installation's shared token */
    const char* name;              /* shown in the server's logs and stats */
    uint32_t role;                 /* HYSAR_ROLE_* */
    uint32_t connect_timeout_ms;   /* per attempt (default 10000) */
    uint32_t reconnect_initial_ms; /* the first back-off (default 250) */
    uint32_t reconnect_max_ms;     /* back-off doubles up to this (default 5000) */
    int32_t reconnect_attempts;    /* -1: forever (default); 0: never; N: give up after N */
    uint32_t keepalive_ms;         /* a Ping after this long without sending (default 20000) */
    uint32_t queue_limit;          /* undelivered images kept; older ones dropped (default 8) */
    /* Since 1.1 (a config of 1.0's size, which ends at queue_limit, is still taken: no TLS).
     * TLS to a server started with --tls-cert/--tls-key; TCP addresses only. */
    uint32_t tls;                /* 1: TLS (implied by either field below); 0: plain (default) */
    const char* tls_ca_file;     /* PEM CA (or the self-signed certificate) the server's must
                                    chain to, its name or IP the address's; NULL: the system's */
    const char* tls_fingerprint; /* the server certificate's SHA-256 ("AB:CD:..." as `hysar serve`
                                    prints it); NULL: not pinned; alone, the pin decides */
} hysar_client_config;

/* A headset's display: per-eye pixels and pinhole intrinsics (OpenCV convention: u right,
 * v down, pixel centres at integers), the interpupillary distance, and what it wants. */
typedef struct hysar_display {
    uint32_t eye_width, eye_height; /* 1..8192 */
    double fx, fy, cx, cy;          /* pixels */
    double ipd_m;                   /* metres, [0, 0.2] */
    uint32_t format;                /* HYSAR_FORMAT_* */
    uint32_t encoding;              /* HYSAR_ENCODING_* */
    uint32_t mode;                  /* HYSAR_MODE_* */
} hysar_display;

/* A head pose in the world frame (+y up, metres): the position of the point between the eyes
 * and the unit quaternion (w, x, y, z) that turns head axes into world axes (the head looks
 * along its -z, +y up). time_ns is the client's clock when the pose was sampled (0: now). */
typedef struct hysar_pose {
    uint64_t time_ns;
    double position_m[3];
    double orientation_wxyz[4];
} hysar_pose;

typedef enum hysar_event_kind {
    HYSAR_EVENT_NONE = 0,            /* hysar_client_poll() timed out */
    HYSAR_EVENT_CONNECTED = 1,       /* a session began (also after a reconnect): session_id,
                                        scene_version, reconnects */
    HYSAR_EVENT_DISCONNECTED = 2,    /* the connection was lost (text: why); reconnecting */
    HYSAR_EVENT_LAYER = 3,           /* a VD layer: eye, frame_id, pose, image */
    HYSAR_EVENT_PROJECTOR_FRAME = 4, /* a projector frame: scene_version, image */
    HYSAR_EVENT_SERVER_ERROR = 5,    /* an Error from the server: error_code, text */
    HYSAR_EVENT_STATS = 6,           /* the answer to hysar_client_request_stats(): text (JSON) */
    HYSAR_EVENT_CLOSED = 7           /* no more events: closed, closed by an operator (error 16:
                                        never reconnected), or reconnecting gave up (text) */
} hysar_event_kind;

typedef struct hysar_image {
    uint32_t width, height;
    uint32_t format;          /* HYSAR_FORMAT_* */
    uint32_t bytes_per_pixel; /* 4 (RGBA8) or 8 (RGBA16F) */
    size_t size_bytes;        /* width * height * bytes_per_pixel */
    const uint8_t* pixels;    /* rows top to bottom, tightly packed */
} hysar_image;

typedef struct hysar_event {
    uint32_t kind;          /* hysar_event_kind */
    uint32_t eye;           /* LAYER: 0 left, 1 right */
    uint32_t frame_id;      /* LAYER: the server's frame counter of this headset */
    uint32_t scene_version; /* CONNECTED, PROJECTOR_FRAME */
    uint32_t session_id;    /* CONNECTED */
    uint32_t error_code;    /* SERVER_ERROR: the protocol's error code */
    uint32_t reconnects;    /* sessions begun after the first one */
    uint32_t reserved_;
    hysar_pose pose;      /* LAYER: the pose the layer was rendered for, as it was sent */
    uint64_t received_ns; /* hysar_now_ns() when the last byte arrived */
    uint64_t decoded_ns;  /* hysar_now_ns() when the pixels were decoded */
    hysar_image image;    /* LAYER, PROJECTOR_FRAME */
    const char* text;     /* never NULL; "" when the kind has none */
    void* internal_;      /* the library's; released by hysar_event_release() */
} hysar_event;

typedef struct hysar_client_info {
    uint32_t connected; /* 1 while a session is up */
    uint32_t session_id;
    uint32_t scene_version;
    uint32_t reconnects;
    uint64_t images_dropped; /* images dropped because the queue was full */
    uint64_t bytes_received;
} hysar_client_info;

/* The library's API version (HYSAR_CLIENT_API_VERSION of the build). */
HYSAR_API uint32_t hysar_client_api_version(void);
/* "ok", "invalid argument", ...; never NULL. */
HYSAR_API const char* hysar_status_name(hysar_status status);
/* The sentence of the last failed call on this thread ("" when none). Valid until the next call
 * into the library on this thread. */
HYSAR_API const char* hysar_last_error(void);
/* The clock of pose time stamps and event times: steady, nanoseconds. */
HYSAR_API uint64_t hysar_now_ns(void);

/* Fills the defaults (struct_size included); address, token and name stay to be set. */
HYSAR_API void hysar_client_config_init(hysar_client_config* config);
/* Reads a headset profile (a JSON file in configs/devices) into a display, its resolution times
 * `scale`; format RGBA8, encoding LOSSY (a server that predates it is asked again for SPARSE),
 * mode CONTINUOUS. */
HYSAR_API hysar_status hysar_display_from_profile(const char* path, double scale,
                                                  hysar_display* out);

/* Connects, sends Hello and waits for Welcome: on HYSAR_OK *out is a client with its session up
 * (the first event is CONNECTED). HYSAR_E_CONNECT or HYSAR_E_REFUSED when this first session
 * cannot be had; later losses are reconnected. */
HYSAR_API hysar_status hysar_client_connect(const hysar_client_config* config, hysar_client** out);
/* Says Bye, stops the network thread and frees the client. NULL is ignored. */
HYSAR_API void hysar_client_close(hysar_client* client);

/* Registers the display (headsets): checked here first, kept and sent again on reconnect. */
HYSAR_API hysar_status hysar_client_register_display(hysar_client* client,
                                                     const hysar_display* display);
/* Sends a pose (time_ns 0: stamped now; *sent_time_ns, when not NULL, gets the stamp). Checked
 * here first. While disconnected the newest pose waits and goes first after the reconnect. */
HYSAR_API hysar_status hysar_client_send_pose(hysar_client* client, const hysar_pose* pose,
                                              uint64_t* sent_time_ns);
/* Asks for one layer pair of the last pose (ON_REQUEST mode); kept across a reconnect until
 * answered. */
HYSAR_API hysar_status hysar_client_request_frame(hysar_client* client);
/* Asks for the server's statistics; the answer is a STATS event. */
HYSAR_API hysar_status hysar_client_request_stats(hysar_client* client);

/* Waits up to timeout_ms (0: do not wait; -1: forever) for the next event. HYSAR_OK with kind
 * NONE on timeout, HYSAR_E_CLOSED after the CLOSED event was taken. Release every event. */
HYSAR_API hysar_status hysar_client_poll(hysar_client* client, int32_t timeout_ms,
                                         hysar_event* out);
/* Frees what an event holds and zeroes it. NULL and zeroed events are ignored. */
HYSAR_API void hysar_event_release(hysar_event* event);

HYSAR_API hysar_status hysar_client_get_info(hysar_client* client, hysar_client_info* out);

/* ---- Time, prediction and late reprojection (library 1.2, added functions only;
 * protocol/PROTOCOL.md, "Time") ----
 *
 * A headset's loop: sample the tracker and hysar_predictor_add() every sample; pick the display
 * time with hysar_next_display_time_ns(now + clock.pose_to_layer_ns, refresh, vsync); send
 * hysar_predictor_predict() of it with hysar_client_send_pose_at(); just before each refresh,
 * hysar_reproject_layer() the newest layer pair to the newest predicted pose and show that. */

/* The clock and latency the library measured this session. */
typedef struct hysar_clock {
    uint32_t samples; /* Ping/Pong samples this session (0: none yet) */
    uint32_t reserved_;
    int64_t offset_ns;         /* server clock - client clock, of the shortest round trip of the
                                  last 16 samples */
    uint64_t round_trip_ns;    /* that sample's round trip */
    uint64_t pose_to_layer_ns; /* median, over the last 32 layers, of the time from a pose's
                                  time_ns to its layer's arrival (0: no layer yet) */
} hysar_clock;
HYSAR_API hysar_status hysar_client_get_clock(hysar_client* client, hysar_clock* out);

/* As hysar_client_send_pose, and the pose says the display (photon) time it is for, on the
 * clock of hysar_now_ns (0: none, as hysar_client_send_pose). The pose should be the one
 * predicted for that time: the server renders it as it is. */
HYSAR_API hysar_status hysar_client_send_pose_at(hysar_client* client, const hysar_pose* pose,
                                                 uint64_t display_time_ns, uint64_t* sent_time_ns);
/* A LAYER event's display time (the one its pose was sent with); 0 when none or not a layer. */
HYSAR_API uint64_t hysar_event_display_time_ns(const hysar_event* event);

typedef struct hysar_predictor hysar_predictor;
typedef struct hysar_predictor_config {
    uint32_t struct_size; /* sizeof(hysar_predictor_config); 48 (API 2, without smooth_ms) is
                             accepted too and gets smooth_ms's default */
    uint32_t reserved_;
    double window_ms;      /* velocities: least-squares slopes over at least the last window_ms
                              of samples (default 40) */
    double filter_ms;      /* their exponential filter's time constant, 0: none (default 20) */
    double max_horizon_ms; /* extrapolate at most this far past the newest sample (default 100) */
    double max_angle_deg;  /* ... nor turn further (default 30) */
    double max_distance_m; /* ... nor move further (default 0.3) */
    /* API 3: the current pose the prediction starts from is the samples' least-squares line at
     * the newest sample, over a window fitted to the tracker's noise and the motion, at most
     * smooth_ms (default 250; 0: the newest sample as it is; README, "Registration") */
    double smooth_ms;
} hysar_predictor_config;
HYSAR_API void hysar_predictor_config_init(hysar_predictor_config* config);
/* config NULL: the defaults. */
HYSAR_API hysar_status hysar_predictor_create(const hysar_predictor_config* config,
                                              hysar_predictor** out);
HYSAR_API void hysar_predictor_destroy(hysar_predictor* predictor);
/* A tracker sample (time_ns must be set). One with a non-finite number, a zero quaternion or a
 * time not after the newest is refused (HYSAR_E_INVALID_ARGUMENT) and changes nothing. */
HYSAR_API hysar_status hysar_predictor_add(hysar_predictor* predictor, const hysar_pose* sample);
/* API 6: a tracker sample with the velocities the tracker measures at it (an inertial unit; an
 * OpenXR runtime's XrSpaceVelocity): angular_velocity in rad/s (axis times rate) and
 * linear_velocity in m/s, both in the world frame of the pose. The predictor then carries the
 * recent samples forward to the newest one's time by the velocities between them and averages
 * them, over a window its measured noises call for (at most 150 ms, smooth_ms when less), so
 * that the current pose's error from the poses' noise falls with the square root of the samples
 * whatever the motion's curvature, and extrapolates the measured velocities (a least-squares
 * line over the last window_ms, unfiltered). Both NULL: as hysar_predictor_add. Refused as
 * hysar_predictor_add refuses, and for one velocity NULL or a non-finite velocity. */
HYSAR_API hysar_status hysar_predictor_add_with_velocity(hysar_predictor* predictor,
                                                         const hysar_pose* sample,
                                                         const double angular_velocity[3],
                                                         const double linear_velocity[3]);
/* The pose predicted for display_time_ns (the smoothed current pose at constant angular and
 * linear velocity, filtered or measured, capped); its time_ns is the newest sample's, so a layer's
 * pose says when it was sampled. HYSAR_E_INVALID_ARGUMENT before the first sample. */
HYSAR_API hysar_status hysar_predictor_predict(const hysar_predictor* predictor,
                                               uint64_t display_time_ns, hysar_pose* out);
/* The first refresh at or after earliest_ns of a display whose refreshes fall at
 * vsync_ns + k / refresh_hz; earliest_ns itself when refresh_hz <= 0. */
HYSAR_API uint64_t hysar_next_display_time_ns(uint64_t earliest_ns, double refresh_hz,
                                              uint64_t vsync_ns);

enum { HYSAR_FILTER_NEAREST = 0, HYSAR_FILTER_BILINEAR = 1 };
/* Late reprojection on the CPU: warps a LAYER event's image from the pose it was rendered for
 * (event->pose, its eye placed by display->ipd_m) to `latest` into dst (dst_bytes >=
 * image.size_bytes, not the event's pixels). plane_depth_m > 0: the points of a plane facing
 * the eye at that distance (metres; the prop's, e.g. from the installation's viewing plan) are
 * put exactly where they belong, the head's translation included; 0: rotation only (a
 * homography per eye from the display's intrinsics, exact for far points);
 * HYSAR_PLANE_DEPTH_FROM_LAYER (since 1.4): the layer's own warp depth, as the server sent it
 * (hysar_event_warp_depth_m; rotation only when it has none).
 * A layer whose pose is older than stale_limit_ns at now_ns (0: no limit) is cleared to 0
 * (see-through: better nothing than a highlight in the wrong place) and *cleared is 1.
 * BILINEAR needs RGBA8; RGBA16F is warped NEAREST. Cost: README ("Registration"). */
HYSAR_API hysar_status hysar_reproject_layer(const hysar_event* layer, const hysar_display* display,
                                             const hysar_pose* latest, uint64_t now_ns,
                                             uint64_t stale_limit_ns, double plane_depth_m,
                                             uint32_t filter, uint8_t* dst, size_t dst_bytes,
                                             uint32_t* cleared);

/* ---- Overscan (library 1.3, API version 3, added functions only) ----
 *
 * A late warp can show only what was rendered: when the head turns, the side it turns to comes
 * into view from outside the layer, and a highlight near the edge of the field of view is cut
 * off there. Register the display widened by a guard band (hysar_display_overscan) and warp
 * each layer back onto the real display (hysar_reproject_layer_to): the server renders the band
 * (its pixels cost render and read-back time there; on the wire only where they are lit). */

/* `display` widened by margin_deg (0..30) of field of view on every side, with the same focal
 * lengths: out's size and principal point are the rendered layer's; out->eye_width/eye_height
 * stay <= 8192. The rest of the display is copied. HYSAR_E_INVALID_ARGUMENT (with a sentence)
 * when a pointer is NULL, the intrinsics are not finite and positive, the margin is outside
 * [0, 30], or the widened display would exceed 8192 pixels or 90 degrees from its centre. */
HYSAR_API hysar_status hysar_display_overscan(const hysar_display* display, double margin_deg,
                                              hysar_display* out);
/* As hysar_reproject_layer, from a layer rendered for `rendered` (the display the session
 * registered, e.g. an overscanned one: the image must be rendered->eye_width x eye_height) onto
 * `shown` (the physical display: dst holds shown->eye_width x eye_height pixels of the image's
 * format, dst_bytes at least that). The eye's pose and ipd are the shown display's. */
HYSAR_API hysar_status hysar_reproject_layer_to(
    const hysar_event* layer, const hysar_display* rendered, const hysar_display* shown,
    const hysar_pose* latest, uint64_t now_ns, uint64_t stale_limit_ns, double plane_depth_m,
    uint32_t filter, uint8_t* dst, size_t dst_bytes, uint32_t* cleared);

/* ---- The server's warp depth (library 1.4, API version 4, added functions only) ----
 *
 * A late warp that knows how far away the prop is moves the layer with the head's translation
 * too, not only its rotation: a visitor walking around the prop sees the highlight stay on it.
 * The server knows the prop; a display registered with HYSAR_OPTION_WARP_DEPTH gets, in every
 * layer, the depth of the plane through the prop's centre along that eye's view axis
 * (protocol/PROTOCOL.md, "Time"). A server that predates the option is asked again without it
 * (its layers then carry none). */
enum { HYSAR_OPTION_WARP_DEPTH = 1 };
/* plane_depth_m of hysar_reproject_layer and hysar_reproject_layer_to: the layer's own. */
#define HYSAR_PLANE_DEPTH_FROM_LAYER (-1.0)
/* As hysar_client_register_display, with options (HYSAR_OPTION_* bits; 0: as that call).
 * HYSAR_E_INVALID_ARGUMENT for a bit this library does not know. */
HYSAR_API hysar_status hysar_client_register_display_opts(hysar_client* client,
                                                          const hysar_display* display,
                                                          uint32_t options);
/* A LAYER event's warp depth: metres along its eye's view axis (> 0), or 0 when it has none
 * (the display did not ask, the prop lies behind the eye, or the event is not a LAYER the
 * library delivered). */
HYSAR_API double hysar_event_warp_depth_m(const hysar_event* event);

/* ---- A destination the library keeps (library 1.5, API version 5, added functions only) ----
 *
 * A layer is black (see-through) but for the highlight, and so is its warp: most of a shown
 * image stays 0 from one refresh to the next. A warp target owns its pixels and remembers where
 * they may be lit, so that each warp into it clears only those places rather than the whole
 * image (at HoloLens resolution, about half of a nearest warp's time). The pixels are the
 * library's: read them, never write them. One thread at a time per target. */
typedef struct hysar_warp_target hysar_warp_target;
/* A width x height target of bytes_per_pixel (4: rgba8, 8: rgba16f), all 0.
 * HYSAR_E_INVALID_ARGUMENT (with a sentence) when out is NULL, a side is outside 1..8192 or
 * bytes_per_pixel is not 4 or 8. */
HYSAR_API hysar_status hysar_warp_target_create(uint32_t width, uint32_t height,
                                                uint32_t bytes_per_pixel, hysar_warp_target** out);
/* NULL is ignored. */
HYSAR_API void hysar_warp_target_destroy(hysar_warp_target* target);
/* The target's pixels, rows top to bottom, width x bytes_per_pixel bytes each (NULL for NULL);
 * valid until the target is destroyed, and what the last warp into it made. */
HYSAR_API const uint8_t* hysar_warp_target_pixels(const hysar_warp_target* target);
/* As hysar_reproject_layer_to, into `target` (shown->eye_width x eye_height at the layer's
 * bytes_per_pixel): the same pixels, bit for bit, for less time. */
HYSAR_API hysar_status hysar_reproject_layer_into(
    const hysar_event* layer, const hysar_display* rendered, const hysar_display* shown,
    const hysar_pose* latest, uint64_t now_ns, uint64_t stale_limit_ns, double plane_depth_m,
    uint32_t filter, hysar_warp_target* target, uint32_t* cleared);

#ifdef __cplusplus
}
#endif

#endif /* HYSAR_CLIENT_H */
