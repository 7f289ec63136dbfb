// Gray-code structured light (paper Sec. 5.1.2, "Spatial Calibration"): the pattern sequence a
// device (projector or headset screen) shows, and the decoding of what a camera captured into a
// dense camera-to-device look-up table. Generation and per-pixel decoding are OpenCV's
// structured_light module; shadow masks, thresholds and validity are ours.
//
// Coordinates follow OpenCV: pixel centres at integers, x right, y down. A decoded device pixel
// (i, j) is the pixel whose centre is (i, j).
#pragma once

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "core/image.hpp"
#include "core/result.hpp"

namespace hs::calib {

// The images a device shows, in order: the Gray-code patterns (each followed by its inverse;
// columns first, then rows, as OpenCV generates them), then full white, then full black.
struct PatternSet {
    uint32_t width = 0, height = 0;  // the device's resolution
    uint32_t pattern_count = 0;      // images before white and black
    std::vector<ImageRgba8> images;  // pattern_count + 2 images, grey in RGB, alpha 255
};
Result<PatternSet> gray_code_patterns(uint32_t width, uint32_t height);

// How many images a device of this size needs (patterns, white and black).
uint32_t gray_code_image_count(uint32_t width, uint32_t height);

struct DecodeOptions {
    // A camera pixel is lit when white - black (grey, camera DN) exceeds this: shadowed pixels
    // and pixels the device does not reach are never decoded.
    double black_threshold = 20;
    // Every bit needs |pattern - inverse| above this (camera DN); a pixel where one bit is
    // ambiguous (an edge, noise) is marked invalid rather than guessed.
    double white_threshold = 4;
};

// Camera pixel to device pixel. x and y are NaN where the pixel is not valid.
struct DeviceLut {
    uint32_t camera_width = 0, camera_height = 0;
    uint32_t device_width = 0, device_height = 0;
    std::vector<float> x, y;      // device pixel per camera pixel
    std::vector<uint8_t> state;   // kShadow, kAmbiguous or kValid per camera pixel
    uint64_t lit = 0, valid = 0;  // counts
    enum : uint8_t { kShadow = 0, kAmbiguous = 1, kValid = 2 };
    bool is_valid(size_t i) const { return state[i] == kValid; }
};

// Progress of a long step: done out of total, for a progress line.
using Progress = std::function<void(uint64_t done, uint64_t total)>;

// Decodes captures of a PatternSet's images (same order, camera values in DN; an 8-bit camera
// image read as 0..255). Grey is the Rec. 709 luma of RGB, rounded and clipped to 8 bits.
// Errors: a wrong number of captures, captures of different sizes (naming the first that
// differs), and a device with no decodable camera pixel (naming how many were lit).
Result<DeviceLut> decode_gray_code(uint32_t device_width, uint32_t device_height,
                                   const std::vector<ImageRgba32f>& captures,
                                   const DecodeOptions& options, const Progress& progress = {});

// A picture of the map: hue from device x, brightness from device y; shadow black, ambiguous
// pixels dark red.
ImageRgba8 lut_picture(const DeviceLut& lut);

}  // namespace hs::calib
