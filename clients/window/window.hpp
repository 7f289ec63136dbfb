// A GLFW window that shows RGBA8 images (hysar-hmd --window, hysar-projector --window).
// Thread: the thread that created it (GLFW's main-thread rule).
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <variant>
#include <vector>

namespace hs::client {

class ImageWindow {
public:
    // `monitor` >= 0 opens full-screen on that monitor (a projector); -1 a normal window of
    // width x height. Returns an error sentence when no display is available.
    static std::variant<std::unique_ptr<ImageWindow>, std::string> open(const std::string& title,
                                                                        uint32_t width,
                                                                        uint32_t height,
                                                                        int monitor);
    ~ImageWindow();

    // Draws `rgba8` (rows top to bottom) scaled to fit the window, keeping its aspect.
    void show(const std::vector<uint8_t>& rgba8, uint32_t width, uint32_t height);
    // Processes window events; false once the user closed the window.
    bool poll();
    // The image last presented by show() (rows top to bottom), for tests and screenshots.
    std::vector<uint8_t> read_back(uint32_t* width, uint32_t* height);

private:
    ImageWindow() = default;
    void* window_ = nullptr;  // GLFWwindow*
    std::vector<uint8_t> shown_;
    uint32_t shown_w_ = 0, shown_h_ = 0;
};

}  // namespace hs::client
