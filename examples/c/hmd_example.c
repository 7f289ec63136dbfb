/* A headset on libhysar-client, in C: what an engine plug-in (a Unity native plug-in, an OpenXR
 * layer) does each frame. It registers a display from a profile, sends a pose that circles the
 * prop, and takes the decoded layers; the library reconnects by itself if the server restarts.
 *
 *   cc hmd_example.c $(pkg-config --cflags --libs hysar-client) -o hmd_example
 *   ./hmd_example ADDRESS TOKEN PROFILE [PAIRS]     (e.g. unix:/tmp/s.sock secret hololens.json)
 */
#include <hysar_client.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* A pose 0.8 m from the prop's centre at (0, 0.745, 0), eyes at 1.10 m, looking at it, at
 * azimuth `a` (radians) about +y: the head looks along its -z. */
static hysar_pose circling_pose(double a) {
    hysar_pose p;
    memset(&p, 0, sizeof p);
    p.position_m[0] = 0.8 * sin(a);
    p.position_m[1] = 1.10;
    p.position_m[2] = 0.8 * cos(a);
    /* Yaw by `a` (turning -z towards the centre), then pitch down towards the prop's centre. */
    const double pitch = -atan2(1.10 - 0.745, 0.8);
    const double cy = cos(a / 2), sy = sin(a / 2), cp = cos(pitch / 2), sp = sin(pitch / 2);
    p.orientation_wxyz[0] = cy * cp;
    p.orientation_wxyz[1] = cy * sp;
    p.orientation_wxyz[2] = sy * cp;
    p.orientation_wxyz[3] = -sy * sp;
    return p;
}

static int fail(const char* what, hysar_status s) {
    fprintf(stderr, "hmd_example: %s: %s (%s)\n", what, hysar_last_error(), hysar_status_name(s));
    return s == HYSAR_E_CONNECT || s == HYSAR_E_REFUSED ? 2 : 1;
}

int main(int argc, char** argv) {
    if (argc < 4) {
        fprintf(stderr, "usage: hmd_example ADDRESS TOKEN PROFILE [PAIRS]\n");
        return 2;
    }
    const int pairs_wanted = argc > 4 ? atoi(argv[4]) : 10;
    hysar_client_config config;
    hysar_client_config_init(&config);
    config.address = argv[1];
    config.token = argv[2];
    config.name = "c-example";
    config.role = HYSAR_ROLE_HMD;

    hysar_display display;
    hysar_status s = hysar_display_from_profile(argv[3], 0.25, &display);
    if (s != HYSAR_OK)
        return fail("profile", s);
    hysar_client* client = NULL;
    if ((s = hysar_client_connect(&config, &client)) != HYSAR_OK)
        return fail("connect", s);
    if ((s = hysar_client_register_display(client, &display)) != HYSAR_OK) {
        hysar_client_close(client);
        return fail("display", s);
    }
    int pairs = 0, errors = 0, frame = 0;
    while (pairs < pairs_wanted && errors == 0) {
        /* The engine's frame: the newest head pose goes out; the server renders the newest. */
        hysar_pose pose = circling_pose(0.05 * frame++);
        if ((s = hysar_client_send_pose(client, &pose, NULL)) != HYSAR_OK)
            break;
        /* Then, until the next frame is due (~30 Hz), whatever the library has decoded. */
        const uint64_t next_frame = hysar_now_ns() + 33000000;
        for (uint64_t now = hysar_now_ns();
             now < next_frame && s == HYSAR_OK && pairs < pairs_wanted; now = hysar_now_ns()) {
            hysar_event e;
            if ((s = hysar_client_poll(client, (int32_t)((next_frame - now) / 1000000), &e)) !=
                HYSAR_OK)
                break;
            switch (e.kind) {
                case HYSAR_EVENT_LAYER:
                    /* A real plug-in uploads e.image.pixels to the eye's overlay texture. */
                    pairs += e.eye == 1;
                    printf("layer frame %u eye %u %ux%u, pose-to-layer %.1f ms\n", e.frame_id,
                           e.eye, e.image.width, e.image.height,
                           (e.received_ns - e.pose.time_ns) * 1e-6);
                    break;
                case HYSAR_EVENT_DISCONNECTED:
                    /* Show nothing (black is see-through) until the library is back. */
                    fprintf(stderr, "hmd_example: connection lost (%s)\n", e.text);
                    break;
                case HYSAR_EVENT_SERVER_ERROR:
                case HYSAR_EVENT_CLOSED:
                    fprintf(stderr, "hmd_example: %s\n", e.text);
                    errors++;
                    break;
            }
            hysar_event_release(&e);
        }
    }
    hysar_client_close(client);
    if (s != HYSAR_OK)
        return fail("run", s);
    printf("%d layer pairs, %d errors\n", pairs, errors);
    return errors ? 1 : 0;
}
