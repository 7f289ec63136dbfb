/* The ABI of libhysar-client from a C translation unit: hysar_client.h compiles as C11, the
 * structs keep the layout of version 1 on LP64 (a change here breaks every compiled plug-in and
 * the Python example's mirror), and every entry point behaves from C as documented without a
 * server: NULLs refused with a sentence, an unreachable server is HYSAR_E_CONNECT, a profile
 * becomes a display. argv[1]: a headset profile; argv[2]: a Unix socket path nobody listens on. */
#include <hysar_client.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#if defined(__LP64__)
_Static_assert(sizeof(hysar_client_config) == 80, "hysar_client_config layout changed");
_Static_assert(offsetof(hysar_client_config, address) == 8, "config.address moved");
_Static_assert(offsetof(hysar_client_config, role) == 32, "config.role moved");
_Static_assert(offsetof(hysar_client_config, queue_limit) == 56, "config.queue_limit moved");
_Static_assert(offsetof(hysar_client_config, tls) == 60, "config.tls moved");
_Static_assert(offsetof(hysar_client_config, tls_fingerprint) == 72,
               "config.tls_fingerprint moved");
_Static_assert(sizeof(hysar_display) == 64, "hysar_display layout changed");
_Static_assert(offsetof(hysar_display, fx) == 8, "display.fx moved");
_Static_assert(offsetof(hysar_display, mode) == 56, "display.mode moved");
_Static_assert(sizeof(hysar_pose) == 64, "hysar_pose layout changed");
_Static_assert(sizeof(hysar_image) == 32, "hysar_image layout changed");
_Static_assert(offsetof(hysar_image, pixels) == 24, "image.pixels moved");
_Static_assert(sizeof(hysar_event) == 160, "hysar_event layout changed");
_Static_assert(offsetof(hysar_event, pose) == 32, "event.pose moved");
_Static_assert(offsetof(hysar_event, image) == 112, "event.image moved");
_Static_assert(offsetof(hysar_event, text) == 144, "event.text moved");
_Static_assert(sizeof(hysar_client_info) == 32, "hysar_client_info layout changed");
#endif
_Static_assert(HYSAR_CLIENT_API_VERSION == 6, "API version");

static int failures = 0;
#define CHECK(cond)                                                                           \
    do {                                                                                      \
        if (!(cond)) {                                                                        \
            fprintf(stderr, "abi_test.c:%d: %s failed (last error: '%s')\n", __LINE__, #cond, \
                    hysar_last_error());                                                      \
            failures++;                                                                       \
        }                                                                                     \
    } while (0)

int main(int argc, char** argv) {
    if (argc < 3) {
        fprintf(stderr, "usage: abi_test PROFILE UNUSED_SOCKET\n");
        return 2;
    }
    CHECK(hysar_client_api_version() == HYSAR_CLIENT_API_VERSION);
    CHECK(strcmp(hysar_status_name(HYSAR_OK), "ok") == 0);
    CHECK(strcmp(hysar_status_name((hysar_status)99), "unknown status") == 0);
    CHECK(hysar_now_ns() > 0);

    hysar_client_config config;
    memset(&config, 0xAB, sizeof config);
    hysar_client_config_init(&config);
    CHECK(config.struct_size == sizeof(hysar_client_config));
    CHECK(config.address == NULL && config.token == NULL);
    CHECK(config.reconnect_attempts == -1 && config.queue_limit > 0);

    hysar_client* client = (hysar_client*)&config; /* must be overwritten with NULL */
    CHECK(hysar_client_connect(&config, &client) == HYSAR_E_INVALID_ARGUMENT);
    CHECK(client == NULL);
    CHECK(strstr(hysar_last_error(), "config.address") != NULL);

    char address[300];
    snprintf(address, sizeof address, "unix:%s", argv[2]);
    config.address = address;
    config.token = "t";
    config.connect_timeout_ms = 2000;
    CHECK(hysar_client_connect(&config, &client) == HYSAR_E_CONNECT);
    CHECK(strstr(hysar_last_error(), argv[2]) != NULL);
    /* TLS: off by default; a Unix socket never speaks it; a malformed pin is named. */
    CHECK(config.tls == 0 && config.tls_ca_file == NULL && config.tls_fingerprint == NULL);
    config.tls = 1;
    CHECK(hysar_client_connect(&config, &client) == HYSAR_E_INVALID_ARGUMENT);
    CHECK(strstr(hysar_last_error(), "Unix socket") != NULL);
    config.tls = 0;
    config.tls_fingerprint = "AB:CD";
    CHECK(hysar_client_connect(&config, &client) == HYSAR_E_INVALID_ARGUMENT);
    CHECK(strstr(hysar_last_error(), "tls_fingerprint") != NULL);
    /* A config of 1.0's size (it ended at queue_limit: 64 bytes on LP64) is still taken and its
     * TLS fields are not read: the garbage pin above is ignored. */
    config.struct_size = 64;
    CHECK(hysar_client_connect(&config, &client) == HYSAR_E_CONNECT);
    config.struct_size = 56;
    CHECK(hysar_client_connect(&config, &client) == HYSAR_E_INVALID_ARGUMENT);
    CHECK(strstr(hysar_last_error(), "struct_size") != NULL);
    config.struct_size = sizeof config;
    config.tls_fingerprint = NULL;

    hysar_display display;
    CHECK(hysar_display_from_profile(argv[1], 0.5, &display) == HYSAR_OK);
    CHECK(display.eye_width > 0 && display.eye_height > 0 && display.fx > 0);
    CHECK(display.format == HYSAR_FORMAT_RGBA8 && display.mode == HYSAR_MODE_CONTINUOUS);
    hysar_pose pose0;
    memset(&pose0, 0, sizeof pose0);
    pose0.orientation_wxyz[0] = 1;
    {
        /* Overscan (API 3): wider on every side, same focal lengths, the rest copied. */
        hysar_display wide;
        CHECK(hysar_display_overscan(&display, 5, &wide) == HYSAR_OK);
        CHECK(wide.eye_width > display.eye_width && wide.eye_height > display.eye_height);
        CHECK(wide.fx == display.fx && wide.fy == display.fy);
        CHECK(wide.cx > display.cx && wide.cy > display.cy && wide.ipd_m == display.ipd_m);
        CHECK(hysar_display_overscan(&display, 31, &wide) == HYSAR_E_INVALID_ARGUMENT);
        CHECK(strstr(hysar_last_error(), "margin_deg") != NULL);
        CHECK(hysar_display_overscan(NULL, 5, &wide) == HYSAR_E_INVALID_ARGUMENT);
        CHECK(hysar_reproject_layer_to(NULL, &display, &wide, &pose0, 0, 0, 0, 0, NULL, 0, NULL) ==
              HYSAR_E_INVALID_ARGUMENT);
    }
    {
        /* The server's warp depth (API 4). */
        hysar_event none;
        memset(&none, 0, sizeof none);
        CHECK(hysar_event_warp_depth_m(NULL) == 0 && hysar_event_warp_depth_m(&none) == 0);
        CHECK(hysar_client_register_display_opts(NULL, &display, HYSAR_OPTION_WARP_DEPTH) ==
              HYSAR_E_INVALID_ARGUMENT);
        CHECK(hysar_client_register_display_opts(NULL, &display, 2) == HYSAR_E_INVALID_ARGUMENT);
        CHECK(strstr(hysar_last_error(), "HYSAR_OPTION_WARP_DEPTH") != NULL);
        /* A layer the library did not deliver has no depth of its own: rotation only. */
        uint8_t px[4 * 4 * 4], out[4 * 4 * 4];
        memset(px, 0, sizeof px);
        hysar_event own;
        memset(&own, 0, sizeof own);
        own.kind = HYSAR_EVENT_LAYER;
        own.pose = pose0;
        own.image.width = own.image.height = 4;
        own.image.format = HYSAR_FORMAT_RGBA8;
        own.image.bytes_per_pixel = 4;
        own.image.size_bytes = sizeof px;
        own.image.pixels = px;
        CHECK(hysar_event_warp_depth_m(&own) == 0);
        hysar_display small = display;
        small.eye_width = small.eye_height = 4;
        CHECK(hysar_reproject_layer(&own, &small, &pose0, 0, 0, HYSAR_PLANE_DEPTH_FROM_LAYER, 0,
                                    out, sizeof out, NULL) == HYSAR_OK);
        CHECK(hysar_reproject_layer(&own, &small, &pose0, 0, 0, -2.0, 0, out, sizeof out, NULL) ==
              HYSAR_E_INVALID_ARGUMENT);
        CHECK(strstr(hysar_last_error(), "plane_depth_m") != NULL);
        /* 1.5: a warp target the library keeps gives the same pixels. */
        hysar_warp_target* target = NULL;
        CHECK(hysar_warp_target_create(4, 4, 4, &target) == HYSAR_OK && target != NULL);
        CHECK(hysar_reproject_layer_into(&own, &small, &small, &pose0, 0, 0, 0, 0, target, NULL) ==
              HYSAR_OK);
        CHECK(hysar_reproject_layer(&own, &small, &pose0, 0, 0, 0, 0, out, sizeof out, NULL) ==
              HYSAR_OK);
        CHECK(target && memcmp(hysar_warp_target_pixels(target), out, sizeof out) == 0);
        CHECK(hysar_reproject_layer_into(&own, &small, &small, &pose0, 0, 0, 0, 0, NULL, NULL) ==
              HYSAR_E_INVALID_ARGUMENT);
        hysar_warp_target_destroy(target);
        CHECK(hysar_warp_target_create(4, 4, 3, &target) == HYSAR_E_INVALID_ARGUMENT);
        CHECK(strstr(hysar_last_error(), "bytes_per_pixel") != NULL && target == NULL);
        hysar_warp_target_destroy(NULL);
        CHECK(hysar_warp_target_pixels(NULL) == NULL);
    }
    CHECK(hysar_display_from_profile("/nonexistent/profile.json", 1, &display) ==
          HYSAR_E_INVALID_ARGUMENT);
    CHECK(strstr(hysar_last_error(), "/nonexistent/profile.json") != NULL);
    CHECK(hysar_display_from_profile(argv[1], 0, &display) == HYSAR_E_INVALID_ARGUMENT);

    hysar_pose pose;
    memset(&pose, 0, sizeof pose);
    hysar_event event;
    CHECK(hysar_client_send_pose(NULL, &pose, NULL) == HYSAR_E_INVALID_ARGUMENT);
    CHECK(hysar_client_register_display(NULL, &display) == HYSAR_E_INVALID_ARGUMENT);
    CHECK(hysar_client_request_frame(NULL) == HYSAR_E_INVALID_ARGUMENT);
    CHECK(hysar_client_request_stats(NULL) == HYSAR_E_INVALID_ARGUMENT);
    CHECK(hysar_client_poll(NULL, 0, &event) == HYSAR_E_INVALID_ARGUMENT);
    CHECK(hysar_client_get_info(NULL, NULL) == HYSAR_E_INVALID_ARGUMENT);
    CHECK(strlen(hysar_last_error()) > 0);
    memset(&event, 0, sizeof event);
    hysar_event_release(&event); /* a zeroed event is ignored */
    hysar_event_release(NULL);
    hysar_client_close(NULL);

    /* The predictor with the tracker's velocities (API 6), from C: a head turning at 1 rad/s
     * about the vertical is predicted 50 ms past its newest sample to the angle it reaches. */
    {
        hysar_predictor* predictor = NULL;
        CHECK(hysar_predictor_create(NULL, &predictor) == HYSAR_OK);
        const double omega[3] = {0, 1, 0}, still[3] = {0, 0, 0};
        hysar_pose sample;
        memset(&sample, 0, sizeof sample);
        for (int i = 0; i <= 50; ++i) {
            const double half = 0.5 * (i * 0.002); /* half the angle turned, radians */
            sample.time_ns = 1000000000ull + (uint64_t)i * 2000000ull;
            sample.orientation_wxyz[0] = cos(half);
            sample.orientation_wxyz[2] = sin(half);
            CHECK(hysar_predictor_add_with_velocity(predictor, &sample, omega, still) == HYSAR_OK);
        }
        hysar_pose ahead;
        CHECK(hysar_predictor_predict(predictor, sample.time_ns + 50000000ull, &ahead) == HYSAR_OK);
        CHECK(fabs(ahead.orientation_wxyz[2] - sin(0.5 * 0.15)) < 1e-9);
        sample.time_ns += 2000000ull;
        CHECK(hysar_predictor_add_with_velocity(predictor, &sample, NULL, still) ==
              HYSAR_E_INVALID_ARGUMENT);
        CHECK(strstr(hysar_last_error(), "angular_velocity") != NULL);
        CHECK(hysar_predictor_add_with_velocity(NULL, &sample, omega, still) ==
              HYSAR_E_INVALID_ARGUMENT);
        hysar_predictor_destroy(predictor);
    }
    if (failures == 0)
        printf("abi_test: the C API behaves as documented from C\n");
    return failures ? 1 : 0;
}
