// What a client's --version prints: its name, the project's version, the git commit it was
// built from and the build type (cmake/Version.cmake writes hysar_version.hpp at build time).
#pragma once

#include "hysar_version.hpp"

#define HYSAR_CLIENT_VERSION_TEXT(program) \
    program " " HYSAR_VERSION "\ncommit: " HYSAR_GIT_COMMIT "\nbuild type: " HYSAR_BUILD_TYPE "\n"
