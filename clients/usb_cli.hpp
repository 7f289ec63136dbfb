// hysar-hmd's USB options (usb_devices.hpp does the work): --list-devices, --watch-devices S,
// --device auto, --device-table DIR, --add-device VID:PID and --devices-dir DIR. Bad values are
// usage errors (Args::fail, exit 2).
#pragma once

#include <set>
#include <string>

#include "clients/net/args.hpp"

namespace hs::client {

// The table of known headsets when --device-table is not given.
std::string default_device_table();

// The local device entries read beside the shipped table when --devices-dir is not given (and
// only when the folder exists); --add-device writes there.
inline constexpr const char* kLocalDevicesDir = "/etc/hysar/devices";

// The options with a value that --add-device brings to hysar-hmd's option list.
inline const std::set<std::string> kAddDeviceOptions = {"--add-device", "--devices-dir"};

// True when the command line asks for --list-devices, --watch-devices or --add-device:
// run_usb_command then does all the work, without a token or a server.
bool wants_usb_command(const Args& args);

// The table is the shipped one (--device-table, or the configs' devices/ folder) with the local
// folder beside it (--devices-dir, else kLocalDevicesDir when it exists; usb_devices.hpp,
// load_device_table). --list-devices: prints the attached USB devices with their names from the
// system's usb.ids (load_system_usb_ids), marks the known headsets and the profile each
// implies, and says which profile a run would use; exit status 0, also without a USB bus or
// without permission to it (a line says so). --watch-devices S: reports known headsets arriving
// and leaving for S seconds (0: until SIGINT or SIGTERM); exit status 0, or 1 with one line when
// the bus cannot be watched. --add-device VID:PID --profile NAME [--devices-dir DIR]: writes a
// local device entry mapping the ids to the table's profile NAME (usb_devices.hpp,
// write_device_entry), reads the table back with it, prints where and the udev line that lets a
// client without root open the device; exit 0, 2 for a bad VID:PID, an unknown profile or ids
// the table has already, 1 when the file cannot be written. `configured_profile` is --profile
// or its default.
int run_usb_command(const Args& args, const std::string& configured_profile);

// The profile a run uses: `configured_profile`, or with --device auto the profile of the one
// known headset attached in the table with the local folder (a line on stderr says which, or why
// the configured one is kept). Two different known headsets attached, or a broken table or
// local entry, are usage errors naming them.
std::string choose_profile(const Args& args, const std::string& configured_profile);

}  // namespace hs::client
