// USB headset discovery for hysar-hmd: the table of known headsets (the "usb" matches of the
// profiles in configs/devices/), matching attached devices against it, and listing and watching
// the USB bus with libusb.
//
// usb_devices.cpp (library hs_usb_table) is pure: the table, the matching and the choice of
// --device auto, testable with descriptor fixtures and no USB bus. usb_enumerate.cpp (library
// hs_usb) is the only file that sees libusb (scripts/check_layers.sh holds it). Nothing here
// throws: failures are sentences.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <variant>
#include <vector>

namespace hs::client {

// One attached USB device. `manufacturer` and `product_name` are read only when the device can
// be opened (`strings_read`); otherwise (no permission, or the device refuses) they are empty and
// the device is known by its ids alone.
struct UsbDescriptor {
    uint16_t vendor = 0, product = 0;
    std::string manufacturer, product_name;
    uint8_t bus = 0, address = 0;
    bool strings_read = false;
};

// "04b8:1234": the ids as lsusb prints them.
std::string usb_id(uint16_t vendor, uint16_t product);
// "bus 001 address 004  04b8:1234  EPSON ..." (or "... (strings not readable)").
std::string describe_usb(const UsbDescriptor& device);

// One "usb" entry of a profile: { "vendor_id": "0x04b8", "product_id": "0x1234", "what": "..." }.
struct UsbIdMatch {
    uint16_t vendor = 0, product = 0;
    std::string what;  // the headset as a person names it
};

// A profile of the table: its "name", its file and its USB matches (empty when its ids are not
// known; such a profile is never picked by --device auto).
struct KnownHeadset {
    std::string name, path;
    std::vector<UsbIdMatch> usb;
};

// "0x04b8" (or "0X04B8"): 0x and 1 to 4 hexadecimal digits; nullopt for anything else.
std::optional<uint16_t> parse_usb_id(std::string_view text);

// Every *.json file in `dir` (sorted by name), each a headset profile with a "name" and an
// optional "usb" array. Returns the table, or a sentence naming the file and the entry at fault:
// not JSON, no "name", a "usb" entry without both ids or with a malformed one, a pair of ids
// listed twice (in one profile or in two), a folder without profiles.
std::variant<std::vector<KnownHeadset>, std::string> load_headset_table(const std::string& dir);

// An attached device that is a known headset: indices into the descriptors and the table.
struct HeadsetMatch {
    size_t device = 0, headset = 0;
    std::string what;
};

// The attached devices whose vendor and product ids are in the table, in the devices' order.
// Vendor ids alone never match (Epson and Microsoft also make printers and mice).
std::vector<HeadsetMatch> match_headsets(const std::vector<UsbDescriptor>& devices,
                                         const std::vector<KnownHeadset>& table);

// What --device auto picks: `headset` (a table index) when the matches imply exactly one profile
// (two devices of the same headset model imply it once); `conflict` (a sentence naming each
// headset, its bus and address and its profile) when they imply several; neither when none.
struct DeviceChoice {
    std::optional<size_t> headset;
    std::string conflict;
};
DeviceChoice choose_headset(const std::vector<UsbDescriptor>& devices,
                            const std::vector<KnownHeadset>& table,
                            const std::vector<HeadsetMatch>& matches);

// ---- libusb (usb_enumerate.cpp, library hs_usb) ----

// The devices on every USB bus this process can see, or a sentence saying why there is no list:
// no USB bus on this machine (a container), no permission to the bus, libusb could not start.
// An empty list means a bus without devices. Never throws.
std::variant<std::vector<UsbDescriptor>, std::string> list_usb_devices();

// An arrival or departure seen by watch_usb_devices. `present` marks the devices already attached
// when the watch started (reported once, as arrivals).
struct UsbEvent {
    bool arrived = true, present = false;
    UsbDescriptor device;
};

// Reports arrivals and departures to `on_event` (on this thread) for `seconds`, or until `stop`
// returns true when `seconds` is 0; `stop` is asked at least every 250 ms. Returns nullopt after
// the watch, or a sentence when it cannot watch: libusb cannot start, or this libusb on this
// system has no hot-plug support (LIBUSB_CAP_HAS_HOTPLUG). Never throws.
std::optional<std::string> watch_usb_devices(double seconds, const std::function<bool()>& stop,
                                             const std::function<void(const UsbEvent&)>& on_event);

}  // namespace hs::client
