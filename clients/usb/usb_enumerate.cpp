// Listing and watching the USB bus with libusb, the stack's library for USB. The only file that
// sees libusb (scripts/check_layers.sh); see usb_devices.hpp.
#include <chrono>
#include <filesystem>
#include <map>
#include <utility>

#include <libusb.h>

#include "clients/usb_table/usb_devices.hpp"

namespace hs::client {

namespace {

std::string libusb_text(int rc) {
    return std::string(libusb_error_name(rc)) + ": " + libusb_strerror(rc);
}

// Why a libusb call that needs the bus failed, as a person can act on it.
std::string bus_failure(const char* what, int rc) {
    if (rc == LIBUSB_ERROR_ACCESS)
        return std::string("no permission to the USB bus (") + what + ": " + libusb_text(rc) +
               "): run as a user allowed to open /dev/bus/usb, e.g. through a udev rule";
#ifdef __linux__
    std::error_code ec;
    if (!std::filesystem::exists("/dev/bus/usb", ec))
        return std::string(
                   "no USB bus visible to this process (no /dev/bus/usb, as in a "
                   "container without USB devices; ") +
               what + ": " + libusb_text(rc) + ")";
#endif
    return std::string("libusb could not start (") + what + ": " + libusb_text(rc) + ")";
}

// A libusb session for one call; libusb_exit on every path.
struct Session {
    libusb_context* ctx = nullptr;
    int rc = LIBUSB_SUCCESS;
    Session() { rc = libusb_init(&ctx); }
    ~Session() {
        if (rc == LIBUSB_SUCCESS && ctx)
            libusb_exit(ctx);
    }
    Session(const Session&) = delete;
    Session& operator=(const Session&) = delete;
};

std::string read_string(libusb_device_handle* h, uint8_t index) {
    if (index == 0)
        return "";
    unsigned char buf[256];
    const int n = libusb_get_string_descriptor_ascii(h, index, buf, sizeof buf);
    if (n <= 0)
        return "";
    std::string s(reinterpret_cast<const char*>(buf), size_t(n));
    for (char& c : s)
        if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f)
            c = '?';
    while (!s.empty() && s.back() == ' ') s.pop_back();
    return s;
}

// The ids and place of `dev`; its strings too when it can be opened.
UsbDescriptor describe_device(libusb_device* dev, bool read_strings) {
    UsbDescriptor d;
    d.bus = libusb_get_bus_number(dev);
    d.address = libusb_get_device_address(dev);
    libusb_device_descriptor desc{};
    if (libusb_get_device_descriptor(dev, &desc) != LIBUSB_SUCCESS)
        return d;
    d.vendor = desc.idVendor;
    d.product = desc.idProduct;
    libusb_device_handle* h = nullptr;
    if (read_strings && libusb_open(dev, &h) == LIBUSB_SUCCESS) {
        d.manufacturer = read_string(h, desc.iManufacturer);
        d.product_name = read_string(h, desc.iProduct);
        d.strings_read = true;
        libusb_close(h);
    }
    return d;
}

// Hot-plug events as libusb hands them over, handled after the callback returns (libusb asks
// callbacks not to open devices).
struct Pending {
    bool arrived;
    bool present;
    libusb_device* device;  // referenced
};
struct WatchState {
    std::vector<Pending> queue;
    bool enumerating = false;
};

int LIBUSB_CALL on_hotplug(libusb_context*, libusb_device* dev, libusb_hotplug_event event,
                           void* user) {
    auto* s = static_cast<WatchState*>(user);
    try {
        s->queue.push_back(
            {event == LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED, s->enumerating, libusb_ref_device(dev)});
    } catch (...) {
        libusb_unref_device(dev);  // out of memory: the event is lost, the watch goes on
    }
    return 0;  // stay registered
}

}  // namespace

std::variant<std::vector<UsbDescriptor>, std::string> list_usb_devices() {
    try {
        Session s;
        if (s.rc != LIBUSB_SUCCESS)
            return bus_failure("libusb_init", s.rc);
        libusb_device** list = nullptr;
        const ssize_t n = libusb_get_device_list(s.ctx, &list);
        if (n < 0)
            return bus_failure("libusb_get_device_list", int(n));
        std::vector<UsbDescriptor> out;
        try {
            for (ssize_t i = 0; i < n; ++i) out.push_back(describe_device(list[i], true));
        } catch (...) {
            libusb_free_device_list(list, 1);
            throw;
        }
        libusb_free_device_list(list, 1);
        return out;
    } catch (const std::exception& e) {
        return std::string("listing the USB devices failed: ") + e.what();
    }
}

std::optional<std::string> watch_usb_devices(double seconds, const std::function<bool()>& stop,
                                             const std::function<void(const UsbEvent&)>& on_event) {
    WatchState state;
    auto release_queue = [&state]() {
        for (auto& p : state.queue) libusb_unref_device(p.device);
        state.queue.clear();
    };
    try {
        if (!libusb_has_capability(LIBUSB_CAP_HAS_HOTPLUG))
            return std::string(
                "this libusb has no hot-plug support on this system (LIBUSB_CAP_HAS_HOTPLUG); "
                "list the devices with --list-devices instead");
        Session s;
        if (s.rc != LIBUSB_SUCCESS)
            return bus_failure("libusb_init", s.rc);
        libusb_hotplug_callback_handle handle = 0;
        state.enumerating = true;  // LIBUSB_HOTPLUG_ENUMERATE: the attached ones, now
        const int rc = libusb_hotplug_register_callback(
            s.ctx,
            libusb_hotplug_event(LIBUSB_HOTPLUG_EVENT_DEVICE_ARRIVED |
                                 LIBUSB_HOTPLUG_EVENT_DEVICE_LEFT),
            LIBUSB_HOTPLUG_ENUMERATE, LIBUSB_HOTPLUG_MATCH_ANY, LIBUSB_HOTPLUG_MATCH_ANY,
            LIBUSB_HOTPLUG_MATCH_ANY, on_hotplug, &state, &handle);
        state.enumerating = false;
        if (rc != LIBUSB_SUCCESS) {
            release_queue();
            return bus_failure("libusb_hotplug_register_callback", rc);
        }
        // The strings of a device that leaves can no longer be read: remembered at arrival.
        std::map<std::pair<uint8_t, uint8_t>, UsbDescriptor> attached;
        auto drain = [&]() {
            auto batch = std::move(state.queue);
            state.queue.clear();
            struct Unref {  // whatever is left when on_event throws
                std::vector<Pending>& b;
                ~Unref() {
                    for (auto& p : b)
                        if (p.device)
                            libusb_unref_device(p.device);
                }
            } guard{batch};
            for (auto& p : batch) {
                UsbEvent ev;
                ev.arrived = p.arrived;
                ev.present = p.present;
                ev.device = describe_device(p.device, ev.arrived);
                libusb_unref_device(p.device);
                p.device = nullptr;
                const auto key = std::pair(ev.device.bus, ev.device.address);
                if (ev.arrived) {
                    attached[key] = ev.device;
                } else if (auto it = attached.find(key); it != attached.end()) {
                    if (it->second.vendor == ev.device.vendor &&
                        it->second.product == ev.device.product)
                        ev.device = it->second;
                    attached.erase(it);
                }
                on_event(ev);
            }
        };
        std::optional<std::string> failure;
        const auto deadline = std::chrono::steady_clock::now() +
                              std::chrono::duration<double>(seconds > 0 ? seconds : 0);
        try {
            drain();
            while (!stop() && (seconds <= 0 || std::chrono::steady_clock::now() < deadline)) {
                timeval tv{0, 250000};
                const int ev = libusb_handle_events_timeout_completed(s.ctx, &tv, nullptr);
                if (ev < 0 && ev != LIBUSB_ERROR_INTERRUPTED) {
                    failure =
                        "watching the USB bus failed (libusb_handle_events: " + libusb_text(ev) +
                        ")";
                    break;
                }
                drain();
            }
        } catch (...) {
            libusb_hotplug_deregister_callback(s.ctx, handle);
            release_queue();
            throw;
        }
        libusb_hotplug_deregister_callback(s.ctx, handle);
        release_queue();
        return failure;
    } catch (const std::exception& e) {
        release_queue();
        return std::string("watching the USB bus failed: ") + e.what();
    } catch (...) {
        release_queue();
        return std::string("watching the USB bus failed: an unknown exception");
    }
}

}  // namespace hs::client
