#include "clients/usb_cli.hpp"

#include <csignal>
#include <cstdio>
#include <filesystem>

#include "clients/common.hpp"
#include "clients/usb_devices.hpp"

namespace hs::client {

namespace {

volatile std::sig_atomic_t g_stop = 0;
extern "C" void on_stop_signal(int) {
    g_stop = 1;
}

std::vector<KnownHeadset> read_table(const Args& args) {
    std::string dir = args.get("--device-table", "");
    if (!args.has("--device-table")) {
        const ConfigFile found = find_config("devices");
        if (found.path.empty())
            args.fail("the known-headset table: " + found.error + "; give --device-table DIR");
        dir = found.path;
    }
    auto table = load_headset_table(dir);
    if (auto* e = std::get_if<std::string>(&table))
        args.fail("--device-table " + *e);
    return std::get<std::vector<KnownHeadset>>(std::move(table));
}

size_t profiles_with_ids(const std::vector<KnownHeadset>& table) {
    size_t n = 0;
    for (const auto& h : table) n += !h.usb.empty();
    return n;
}

std::string headset_name(const KnownHeadset& h, const std::string& what) {
    return what.empty() ? h.name : what;
}

int list_devices(const Args& args, const std::vector<KnownHeadset>& table,
                 const std::string& configured) {
    const std::string keep = "the configured profile will be used: " + configured +
                             (args.has("--profile") ? " (--profile)" : " (the default --profile)");
    auto listed = list_usb_devices();
    if (auto* e = std::get_if<std::string>(&listed)) {
        std::printf("No USB devices listed: %s.\nNo headset detected: %s\n", e->c_str(),
                    keep.c_str());
        return 0;
    }
    const auto& devices = std::get<std::vector<UsbDescriptor>>(listed);
    const auto matches = match_headsets(devices, table);
    if (devices.empty()) {
        std::error_code ec;
        std::printf("USB devices: none%s\n",
                    std::filesystem::exists("/dev/bus/usb", ec)
                        ? ""
                        : " (no /dev/bus/usb: this machine or container shows no USB bus)");
    } else {
        std::printf("USB devices: %zu\n", devices.size());
    }
    size_t unreadable = 0;
    for (size_t d = 0; d < devices.size(); ++d) {
        std::string line = "  " + describe_usb(devices[d]);
        for (const auto& m : matches)
            if (m.device == d)
                line += "  <- known headset: " + headset_name(table[m.headset], m.what) +
                        ", profile " + table[m.headset].path;
        std::printf("%s\n", line.c_str());
        unreadable += !devices[d].strings_read;
    }
    if (unreadable)
        std::printf(
            "(%zu of %zu devices could not be opened to read their names, most likely no "
            "permission to the USB bus: they are known by their ids)\n",
            unreadable, devices.size());
    const DeviceChoice choice = choose_headset(devices, table, matches);
    if (choice.headset) {
        std::printf("Known headset attached: --device auto uses the profile %s\n",
                    table[*choice.headset].path.c_str());
    } else if (!choice.conflict.empty()) {
        std::printf("--device auto would refuse to choose: %s.\nWithout --device auto, %s\n",
                    choice.conflict.c_str(), keep.c_str());
    } else {
        std::printf(
            "No known headset attached (%zu of %zu profiles in the table list USB ids): "
            "%s\nTo add a headset, copy a profile and put the ids lsusb shows for it in "
            "its \"usb\" array (configs/devices/README.md).\n",
            profiles_with_ids(table), table.size(), keep.c_str());
    }
    return 0;
}

int watch_devices(const Args& args, const std::vector<KnownHeadset>& table) {
    const double seconds = args.number("--watch-devices", 0, 0, 86400);
    const std::string how_long =
        seconds > 0 ? "for " + format_number(seconds) + " s" : "until SIGINT (Ctrl-C) or SIGTERM";
    std::printf(
        "Watching the USB bus %s: known headsets are the %zu of %zu profiles in %s with "
        "USB ids; other devices are shown as they come and go.\n",
        how_long.c_str(), profiles_with_ids(table), table.size(),
        args.get("--device-table", default_device_table()).c_str());
    std::fflush(stdout);
    g_stop = 0;
    std::signal(SIGINT, on_stop_signal);
    std::signal(SIGTERM, on_stop_signal);
    size_t arrivals = 0, departures = 0;
    auto report = [&](const UsbEvent& ev) {
        const auto matches = match_headsets({ev.device}, table);
        if (matches.empty()) {
            if (!ev.present)  // what was attached before the watch is not news
                std::printf("%s (not a known headset): %s\n", ev.arrived ? "arrived" : "left",
                            describe_usb(ev.device).c_str());
        } else {
            for (const auto& m : matches)
                std::printf("%s: %s  %s  profile %s\n",
                            ev.present   ? "present"
                            : ev.arrived ? "arrived"
                                         : "left",
                            headset_name(table[m.headset], m.what).c_str(),
                            describe_usb(ev.device).c_str(), table[m.headset].path.c_str());
            if (!ev.present)
                ++(ev.arrived ? arrivals : departures);
        }
        std::fflush(stdout);
    };
    auto failure = watch_usb_devices(
        seconds, [] { return g_stop != 0; }, report);
    std::signal(SIGINT, SIG_DFL);
    std::signal(SIGTERM, SIG_DFL);
    if (failure) {
        std::fprintf(stderr, "hysar-hmd: --watch-devices: %s\n", failure->c_str());
        return 1;
    }
    std::printf("Watch ended: %zu arrivals and %zu departures of known headsets.\n", arrivals,
                departures);
    return 0;
}

}  // namespace

std::string default_device_table() {
    const ConfigFile table = find_config("devices");
    return table.path.empty() ? config_dirs().front() + "/devices" : table.path;
}

bool wants_usb_command(const Args& args) {
    return args.has("--list-devices") || args.has("--watch-devices");
}

int run_usb_command(const Args& args, const std::string& configured) {
    if (args.has("--list-devices") && args.has("--watch-devices"))
        args.fail("give --list-devices or --watch-devices, not both");
    const auto table = read_table(args);
    if (args.has("--watch-devices"))
        return watch_devices(args, table);
    protocol::RegisterDisplay display;
    if (auto err = load_profile(configured, 1.0, &display))
        args.fail("--profile " + *err);
    return list_devices(args, table, configured);
}

std::string choose_profile(const Args& args, const std::string& configured) {
    if (!args.has("--device")) {
        if (args.has("--device-table"))
            args.fail(
                "--device-table is read by --device auto, --list-devices and "
                "--watch-devices only");
        return configured;
    }
    args.choice("--device", "auto", {"auto"});
    const auto table = read_table(args);
    auto listed = list_usb_devices();
    if (auto* e = std::get_if<std::string>(&listed)) {
        std::fprintf(stderr, "hysar-hmd: --device auto: %s; using the configured profile %s\n",
                     e->c_str(), configured.c_str());
        return configured;
    }
    const auto& devices = std::get<std::vector<UsbDescriptor>>(listed);
    const auto matches = match_headsets(devices, table);
    const DeviceChoice choice = choose_headset(devices, table, matches);
    if (!choice.conflict.empty())
        args.fail("--device auto: " + choice.conflict +
                  "; unplug all but one, or leave out --device auto and give --profile");
    if (!choice.headset) {
        std::fprintf(stderr,
                     "hysar-hmd: --device auto: no known headset among the %zu USB devices; "
                     "using the configured profile %s\n",
                     devices.size(), configured.c_str());
        return configured;
    }
    const std::string& chosen = table[*choice.headset].path;
    protocol::RegisterDisplay display;
    if (auto err = load_profile(chosen, 1.0, &display))
        args.fail("--device auto: the attached headset's profile " + *err);
    for (const auto& m : matches)
        if (m.headset == *choice.headset) {
            std::fprintf(stderr, "hysar-hmd: --device auto: %s (%s) -> profile %s\n",
                         headset_name(table[m.headset], m.what).c_str(),
                         describe_usb(devices[m.device]).c_str(), chosen.c_str());
            break;
        }
    return chosen;
}

}  // namespace hs::client
