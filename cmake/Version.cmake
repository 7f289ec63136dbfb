# The version header of every binary's --version: `hysar_version.hpp` with HYSAR_VERSION (the
# project's VERSION), HYSAR_GIT_COMMIT (the checkout's commit, "-dirty" when tracked files
# differ from it, "unknown" outside a git checkout or without git) and HYSAR_BUILD_TYPE.
#
# Included from a CMakeLists.txt it defines the INTERFACE target hs_version (the header's
# folder, and the target that writes it). That target runs at every build and rewrites the
# header only when its text changes, so a new commit is picked up by the next build without
# recompiling anything when nothing changed. Run with `cmake -P` it writes the header.
if(CMAKE_SCRIPT_MODE_FILE)
    set(commit "unknown")
    find_package(Git QUIET)
    if(GIT_FOUND)
        execute_process(COMMAND ${GIT_EXECUTABLE} -C "${HYSAR_SOURCE_DIR}" rev-parse --short=12 HEAD
                        OUTPUT_VARIABLE head RESULT_VARIABLE rc ERROR_QUIET
                        OUTPUT_STRIP_TRAILING_WHITESPACE)
        if(rc EQUAL 0 AND head)
            set(commit "${head}")
            execute_process(COMMAND ${GIT_EXECUTABLE} -C "${HYSAR_SOURCE_DIR}" status --porcelain
                                    --untracked-files=no
                            OUTPUT_VARIABLE changes RESULT_VARIABLE rc ERROR_QUIET)
            if(rc EQUAL 0 AND NOT changes STREQUAL "")
                string(APPEND commit "-dirty")
            endif()
        endif()
    endif()
    set(text "// Written by cmake/Version.cmake at build time; do not edit.\n#pragma once\n")
    string(APPEND text "#define HYSAR_VERSION \"${HYSAR_VERSION}\"\n")
    string(APPEND text "#define HYSAR_GIT_COMMIT \"${commit}\"\n")
    string(APPEND text "#define HYSAR_BUILD_TYPE \"${HYSAR_BUILD_TYPE}\"\n")
    set(old "")
    if(EXISTS "${HYSAR_VERSION_HEADER}")
        file(READ "${HYSAR_VERSION_HEADER}" old)
    endif()
    if(NOT old STREQUAL text)
        file(WRITE "${HYSAR_VERSION_HEADER}" "${text}")
    endif()
    return()
endif()

include_guard(GLOBAL)
set(HYSAR_VERSION_DIR ${PROJECT_BINARY_DIR}/generated/version)
set(HYSAR_VERSION_HEADER ${HYSAR_VERSION_DIR}/hysar_version.hpp)
set(_hysar_build_type "${CMAKE_BUILD_TYPE}")
if(_hysar_build_type STREQUAL "")
    set(_hysar_build_type "none")
endif()
add_custom_target(hs_version_header
    COMMAND ${CMAKE_COMMAND} -DHYSAR_SOURCE_DIR=${PROJECT_SOURCE_DIR}
            -DHYSAR_VERSION=${PROJECT_VERSION} -DHYSAR_BUILD_TYPE=${_hysar_build_type}
            -DHYSAR_VERSION_HEADER=${HYSAR_VERSION_HEADER} -P ${PROJECT_SOURCE_DIR}/cmake/Version.cmake
    BYPRODUCTS ${HYSAR_VERSION_HEADER}
    COMMENT "Version header (git commit)"
    VERBATIM)
add_library(hs_version INTERFACE)
target_include_directories(hs_version INTERFACE ${HYSAR_VERSION_DIR})
add_dependencies(hs_version hs_version_header)
