#include "clients/window/window.hpp"

#include <algorithm>

#define GLFW_INCLUDE_NONE
#include <GL/gl.h>
#include <GLFW/glfw3.h>

namespace hs::client {

namespace {
std::string g_last_error;
void on_error(int, const char* text) {
    g_last_error = text ? text : "unknown GLFW error";
}
}  // namespace

std::variant<std::unique_ptr<ImageWindow>, std::string> ImageWindow::open(const std::string& title,
                                                                          uint32_t w, uint32_t h,
                                                                          int monitor) {
    glfwSetErrorCallback(on_error);
    if (!glfwInit())
        return "cannot open a window (no display? set DISPLAY or run under xvfb-run): " +
               g_last_error;
    GLFWmonitor* mon = nullptr;
    if (monitor >= 0) {
        int count = 0;
        GLFWmonitor** mons = glfwGetMonitors(&count);
        if (monitor >= count) {
            glfwTerminate();
            return "monitor " + std::to_string(monitor) + " does not exist (" +
                   std::to_string(count) + " connected)";
        }
        mon = mons[monitor];
        const GLFWvidmode* mode = glfwGetVideoMode(mon);
        w = uint32_t(mode->width);
        h = uint32_t(mode->height);
    }
    glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 2);
    glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 1);
    glfwWindowHint(GLFW_RESIZABLE, GLFW_TRUE);
    GLFWwindow* win = glfwCreateWindow(int(w), int(h), title.c_str(), mon, nullptr);
    if (!win) {
        glfwTerminate();
        return "cannot create a window: " + g_last_error;
    }
    glfwMakeContextCurrent(win);
    glfwSwapInterval(1);
    std::unique_ptr<ImageWindow> iw(new ImageWindow());
    iw->window_ = win;
    glClearColor(0, 0, 0, 1);
    glClear(GL_COLOR_BUFFER_BIT);
    glfwSwapBuffers(win);
    return iw;
}

ImageWindow::~ImageWindow() {
    if (window_)
        glfwDestroyWindow(static_cast<GLFWwindow*>(window_));
    glfwTerminate();
}

void ImageWindow::show(const std::vector<uint8_t>& rgba8, uint32_t w, uint32_t h) {
    auto* win = static_cast<GLFWwindow*>(window_);
    int fw = 0, fh = 0;
    glfwGetFramebufferSize(win, &fw, &fh);
    glViewport(0, 0, fw, fh);
    glClear(GL_COLOR_BUFFER_BIT);
    if (w && h && rgba8.size() == size_t(w) * h * 4) {
        // Fit, centred; rows are drawn top-down by a negative vertical zoom from the top edge.
        const float s = std::min(float(fw) / float(w), float(fh) / float(h));
        const float x0 = 0.5f * (float(fw) - s * float(w)),
                    y_top = 0.5f * (float(fh) + s * float(h));
        glMatrixMode(GL_PROJECTION);
        glLoadIdentity();
        glOrtho(0, fw, 0, fh, -1, 1);
        glMatrixMode(GL_MODELVIEW);
        glLoadIdentity();
        glRasterPos2f(x0, y_top - 0.001f);
        glPixelZoom(s, -s);
        glPixelStorei(GL_UNPACK_ALIGNMENT, 1);
        glDrawPixels(GLsizei(w), GLsizei(h), GL_RGBA, GL_UNSIGNED_BYTE, rgba8.data());
    }
    glFinish();
    // Keep what is about to be presented: reading the front buffer after the swap is
    // undefined on some GLX implementations.
    shown_.resize(size_t(fw) * fh * 4);
    glReadBuffer(GL_BACK);
    glPixelStorei(GL_PACK_ALIGNMENT, 1);
    glReadPixels(0, 0, fw, fh, GL_RGBA, GL_UNSIGNED_BYTE, shown_.data());
    shown_w_ = uint32_t(fw);
    shown_h_ = uint32_t(fh);
    glfwSwapBuffers(win);
}

bool ImageWindow::poll() {
    glfwPollEvents();
    return !glfwWindowShouldClose(static_cast<GLFWwindow*>(window_));
}

std::vector<uint8_t> ImageWindow::read_back(uint32_t* w, uint32_t* h) {
    const uint32_t fw = shown_w_, fh = shown_h_;
    std::vector<uint8_t> flipped(shown_.size());
    for (uint32_t y = 0; y < fh; ++y)
        std::copy_n(&shown_[size_t(fh - 1 - y) * fw * 4], size_t(fw) * 4,
                    &flipped[size_t(y) * fw * 4]);
    *w = fw;
    *h = fh;
    return flipped;
}

}  // namespace hs::client
