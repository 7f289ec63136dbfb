#include "render/probe.hpp"

#include <glm/gtc/constants.hpp>

#include "gpu/commands.hpp"
#include "gpu/shared_layout.hpp"
#include "render/renderer.hpp"
#include "shaders/probe_comp.h"
#include "shaders/probe_comp_f32.h"

namespace hs::render {

Result<std::vector<ProbeResult>> run_shading_probe(gpu::Device& device, const scene::Specular& spec,
                                                   const std::vector<ProbeCase>& cases) {
    if (cases.empty())
        return std::vector<ProbeResult>{};
    gpu::ComputePipelineInfo pi;
    pi.spv = device.float64() ? std::span<const uint32_t>(kProbeCompSpv)
                              : std::span<const uint32_t>(kProbeCompSpvF32);
    pi.spec.set_int(HS_SC_SPEC_MODEL, int(spec.model))
        .set_bool(HS_SC_ANISOTROPIC, spec.anisotropic())
        .set_int(HS_SC_LOBE_EXPONENT, whole_exponent(spec));
    pi.storage_buffers = 2;
    pi.push_constant_bytes = 4;
    pi.name = "pipeline.shading-probe";
    HS_ASSIGN_OR_RETURN(auto pipeline, gpu::ComputePipeline::create(device, pi));
    std::vector<gpu::GpuProbeCase> in(cases.size());
    for (size_t i = 0; i < cases.size(); ++i) {
        in[i].n = glm::vec4(glm::vec3(cases[i].n), 0);
        const auto& c = cases[i];
        in[i].l = c.point_light ? glm::vec4(glm::vec3(c.light_position), 1)
                                : glm::vec4(glm::vec3(c.l), 0);
        in[i].p = glm::vec4(glm::vec3(c.p), 1);
        in[i].material = glm::vec4(float(c.intensity), float(c.albedo / glm::pi<double>()),
                                   float(c.specular_colour), 0);
        in[i].v = glm::vec4(glm::vec3(cases[i].v), 0);
        in[i].t = glm::vec4(glm::vec3(cases[i].tangent_axis), 0);
        in[i].params = glm::vec4(float(spec.exponent), float(spec.alpha_x), float(spec.alpha_y),
                                 float(c.min_distance));
    }
    HS_ASSIGN_OR_RETURN(auto in_buf, gpu::Buffer::create(device, in.size() * sizeof(in[0]),
                                                         gpu::BufferUsage::kStorage, "probe.in"));
    HS_ASSIGN_OR_RETURN(auto out_buf,
                        gpu::Buffer::create(device, in.size() * sizeof(gpu::GpuProbeResult),
                                            gpu::BufferUsage::kStorage, "probe.out"));
    in_buf.write(in.data(), in.size() * sizeof(in[0]));
    pipeline.bind_storage(device, HS_BINDING_PROBE_IN, in_buf);
    pipeline.bind_storage(device, HS_BINDING_PROBE_OUT, out_buf);
    uint32_t count = uint32_t(cases.size());
    HS_TRY(gpu::execute(device, "pass.shading-probe", [&](gpu::CommandList& cl) {
        cl.dispatch(pipeline, &count, 4, (count + HS_PROBE_LOCAL_SIZE - 1) / HS_PROBE_LOCAL_SIZE);
    }));
    const auto* res = static_cast<const gpu::GpuProbeResult*>(out_buf.mapped());
    std::vector<ProbeResult> out(cases.size());
    for (size_t i = 0; i < cases.size(); ++i)
        out[i] = {res[i].value.x,    res[i].value.y,    res[i].radiance.x,
                  res[i].radiance.y, res[i].radiance.z, res[i].radiance.w};
    return out;
}

}  // namespace hs::render
