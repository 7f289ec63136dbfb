#!/usr/bin/env python3
"""A headset on libhysar-client from Python, with ctypes only (no build step).

    python3 hmd_example.py ADDRESS TOKEN PROFILE [PAIRS] [--lib PATH] [--save FILE.ppm]

It registers a display from a headset profile, sends a pose that circles the prop, and receives
the decoded layers; the library reconnects by itself if the server restarts. The structs below
mirror hysar_client.h (version 1); the library is found as libhysar-client.so.1 or by --lib.
"""
import ctypes as C
import math
import sys


class Config(C.Structure):
    _fields_ = [("struct_size", C.c_uint32), ("address", C.c_char_p), ("token", C.c_char_p),
                ("name", C.c_char_p), ("role", C.c_uint32), ("connect_timeout_ms", C.c_uint32),
                ("reconnect_initial_ms", C.c_uint32), ("reconnect_max_ms", C.c_uint32),
                ("reconnect_attempts", C.c_int32), ("keepalive_ms", C.c_uint32),
                ("queue_limit", C.c_uint32), ("tls", C.c_uint32), ("tls_ca_file", C.c_char_p),
                ("tls_fingerprint", C.c_char_p)]


class Display(C.Structure):
    _fields_ = [("eye_width", C.c_uint32), ("eye_height", C.c_uint32), ("fx", C.c_double),
                ("fy", C.c_double), ("cx", C.c_double), ("cy", C.c_double), ("ipd_m", C.c_double),
                ("format", C.c_uint32), ("encoding", C.c_uint32), ("mode", C.c_uint32)]


class Pose(C.Structure):
    _fields_ = [("time_ns", C.c_uint64), ("position_m", C.c_double * 3),
                ("orientation_wxyz", C.c_double * 4)]


class Image(C.Structure):
    _fields_ = [("width", C.c_uint32), ("height", C.c_uint32), ("format", C.c_uint32),
                ("bytes_per_pixel", C.c_uint32), ("size_bytes", C.c_size_t),
                ("pixels", C.POINTER(C.c_uint8))]


class Event(C.Structure):
    _fields_ = [("kind", C.c_uint32), ("eye", C.c_uint32), ("frame_id", C.c_uint32),
                ("scene_version", C.c_uint32), ("session_id", C.c_uint32),
                ("error_code", C.c_uint32), ("reconnects", C.c_uint32), ("reserved_", C.c_uint32),
                ("pose", Pose), ("received_ns", C.c_uint64), ("decoded_ns", C.c_uint64),
                ("image", Image), ("text", C.c_char_p), ("internal_", C.c_void_p)]


OK, ROLE_HMD = 0, 2
EVENT_LAYER, EVENT_DISCONNECTED, EVENT_SERVER_ERROR, EVENT_CLOSED = 3, 2, 5, 7


def load(path):
    lib = C.CDLL(path)
    lib.hysar_last_error.restype = C.c_char_p
    lib.hysar_status_name.restype = C.c_char_p
    lib.hysar_client_api_version.restype = C.c_uint32
    lib.hysar_now_ns.restype = C.c_uint64
    lib.hysar_client_connect.argtypes = [C.POINTER(Config), C.POINTER(C.c_void_p)]
    lib.hysar_client_close.argtypes = [C.c_void_p]
    lib.hysar_client_register_display.argtypes = [C.c_void_p, C.POINTER(Display)]
    lib.hysar_client_send_pose.argtypes = [C.c_void_p, C.POINTER(Pose), C.POINTER(C.c_uint64)]
    lib.hysar_client_poll.argtypes = [C.c_void_p, C.c_int32, C.POINTER(Event)]
    lib.hysar_event_release.argtypes = [C.POINTER(Event)]
    lib.hysar_display_from_profile.argtypes = [C.c_char_p, C.c_double, C.POINTER(Display)]
    return lib


def circling_pose(a):
    """0.8 m from the prop's centre (0, 0.745, 0), eyes at 1.10 m, looking at it (head -z)."""
    pitch = -math.atan2(1.10 - 0.745, 0.8)
    cy, sy, cp, sp = math.cos(a / 2), math.sin(a / 2), math.cos(pitch / 2), math.sin(pitch / 2)
    return Pose(0, (C.c_double * 3)(0.8 * math.sin(a), 1.10, 0.8 * math.cos(a)),
                (C.c_double * 4)(cy * cp, cy * sp, sy * cp, -sy * sp))


def main(argv):
    args = [a for a in argv[1:]]
    lib_path, save = "libhysar-client.so.1", None
    if "--lib" in args:
        i = args.index("--lib"); lib_path = args[i + 1]; del args[i:i + 2]
    if "--save" in args:
        i = args.index("--save"); save = args[i + 1]; del args[i:i + 2]
    if len(args) < 3:
        print(__doc__, file=sys.stderr)
        return 2
    address, token, profile = args[0], args[1], args[2]
    pairs_wanted = int(args[3]) if len(args) > 3 else 10
    lib = load(lib_path)
    err = lambda: lib.hysar_last_error().decode()

    config = Config()
    lib.hysar_client_config_init(C.byref(config))
    config.address, config.token, config.name = address.encode(), token.encode(), b"py-example"
    config.role = ROLE_HMD
    display = Display()
    if lib.hysar_display_from_profile(profile.encode(), 0.25, C.byref(display)) != OK:
        print("hmd_example.py: profile:", err(), file=sys.stderr)
        return 2
    client = C.c_void_p()
    status = lib.hysar_client_connect(C.byref(config), C.byref(client))
    if status != OK:
        print("hmd_example.py: connect:", err(), file=sys.stderr)
        return 2
    pairs, errors, frame = 0, 0, 0
    try:
        if lib.hysar_client_register_display(client, C.byref(display)) != OK:
            print("hmd_example.py: display:", err(), file=sys.stderr)
            return 1
        while pairs < pairs_wanted and errors == 0:
            pose = circling_pose(0.05 * frame)
            frame += 1
            if lib.hysar_client_send_pose(client, C.byref(pose), None) != OK:
                print("hmd_example.py: pose:", err(), file=sys.stderr)
                return 1
            # Then, until the next frame is due (~30 Hz), whatever the library has decoded.
            next_frame = lib.hysar_now_ns() + 33_000_000
            while (now := lib.hysar_now_ns()) < next_frame and pairs < pairs_wanted:
                e = Event()
                if lib.hysar_client_poll(client, (next_frame - now) // 1_000_000, C.byref(e)) != OK:
                    print("hmd_example.py: poll:", err(), file=sys.stderr)
                    return 1
                try:
                    if e.kind == EVENT_LAYER:
                        pairs += e.eye == 1
                        latency_ms = (e.received_ns - e.pose.time_ns) * 1e-6
                        print(f"layer frame {e.frame_id} eye {e.eye} {e.image.width}x{e.image.height},"
                              f" pose-to-layer {latency_ms:.1f} ms")
                        if save and e.eye == 0 and e.image.bytes_per_pixel == 4:
                            # The pixels are the library's until release: copy what is kept.
                            px = C.string_at(e.image.pixels, e.image.size_bytes)
                            rgb = bytes(b for i, b in enumerate(px) if i % 4 != 3)
                            with open(save, "wb") as f:
                                f.write(b"P6 %d %d 255\n" % (e.image.width, e.image.height) + rgb)
                    elif e.kind == EVENT_DISCONNECTED:
                        print("hmd_example.py: connection lost:", e.text.decode(), file=sys.stderr)
                    elif e.kind in (EVENT_SERVER_ERROR, EVENT_CLOSED):
                        print("hmd_example.py:", e.text.decode(), file=sys.stderr)
                        errors += 1
                finally:
                    lib.hysar_event_release(C.byref(e))
    finally:
        lib.hysar_client_close(client)
    print(f"{pairs} layer pairs, {errors} errors")
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
