// The only file that sees tinygltf. Every accessor is bounds-checked before it is read, so a
// malformed file is an error naming the file and the problem, never a crash.
#include <cstring>
#include <filesystem>

#include <fmt/format.h>
#include <tiny_gltf.h>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>

#include "scene/mesh.hpp"

namespace hs::scene {

namespace {

Error gltf_error(const std::string& path, const std::string& what) {
    return make_error(ErrorCode::kParse, fmt::format("{}: {}", path, what));
}

// Reads accessor `index` as `comps` floats (or integers for indices) per element.
Result<std::vector<double>> read_accessor(const tinygltf::Model& model, int index, int want_type,
                                          const std::string& path, const char* what) {
    if (index < 0 || size_t(index) >= model.accessors.size())
        return gltf_error(path, fmt::format("{}: accessor {} does not exist", what, index));
    const auto& acc = model.accessors[index];
    if (acc.type != want_type)
        return gltf_error(path, fmt::format("{}: accessor {} has type {}, expected {}", what, index,
                                            acc.type, want_type));
    if (acc.bufferView < 0 || size_t(acc.bufferView) >= model.bufferViews.size())
        return gltf_error(path,
                          fmt::format("{}: accessor {} has no valid bufferView", what, index));
    if (acc.sparse.isSparse)
        return gltf_error(path, fmt::format("{}: sparse accessors are not supported", what));
    const auto& view = model.bufferViews[acc.bufferView];
    if (view.buffer < 0 || size_t(view.buffer) >= model.buffers.size())
        return gltf_error(
            path, fmt::format("{}: bufferView {} has no valid buffer", what, acc.bufferView));
    const auto& buf = model.buffers[view.buffer];
    const int comps = tinygltf::GetNumComponentsInType(acc.type);
    const int csize = tinygltf::GetComponentSizeInBytes(acc.componentType);
    if (comps <= 0 || csize <= 0)
        return gltf_error(path, fmt::format("{}: unknown component type", what));
    const size_t elem = size_t(comps) * csize;
    const size_t stride = view.byteStride ? view.byteStride : elem;
    const size_t begin = view.byteOffset + acc.byteOffset;
    if (acc.count == 0)
        return std::vector<double>{};
    const size_t last = begin + stride * (acc.count - 1) + elem;
    if (stride < elem || last > view.byteOffset + view.byteLength || last > buf.data.size())
        return gltf_error(
            path, fmt::format("{}: accessor {} reads past the end of its buffer", what, index));
    std::vector<double> out(acc.count * comps);
    for (size_t i = 0; i < acc.count; ++i) {
        const unsigned char* p = buf.data.data() + begin + i * stride;
        for (int c = 0; c < comps; ++c) {
            const unsigned char* q = p + size_t(c) * csize;
            double v = 0;
            switch (acc.componentType) {
                case TINYGLTF_COMPONENT_TYPE_FLOAT: {
                    float f;
                    std::memcpy(&f, q, 4);
                    v = f;
                    break;
                }
                case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
                    uint32_t u;
                    std::memcpy(&u, q, 4);
                    v = u;
                    break;
                }
                case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
                    uint16_t u;
                    std::memcpy(&u, q, 2);
                    v = u;
                    break;
                }
                case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE:
                    v = *q;
                    break;
                default:
                    return gltf_error(path, fmt::format("{}: component type {} is not supported",
                                                        what, acc.componentType));
            }
            out[i * comps + c] = v;
        }
    }
    return out;
}

glm::dmat4 node_matrix(const tinygltf::Node& n) {
    if (n.matrix.size() == 16)
        return glm::make_mat4(n.matrix.data());
    glm::dmat4 t(1.0), r(1.0), s(1.0);
    if (n.translation.size() == 3)
        t[3] = glm::dvec4(n.translation[0], n.translation[1], n.translation[2], 1);
    if (n.rotation.size() == 4)
        r = glm::mat4_cast(glm::dquat(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2]));
    if (n.scale.size() == 3)
        s = glm::scale(glm::dmat4(1.0), glm::dvec3(n.scale[0], n.scale[1], n.scale[2]));
    return t * r * s;
}

Result<void> append_mesh(const tinygltf::Model& model, int mesh_index, const glm::dmat4& xf,
                         const std::string& path, Mesh& out) {
    if (mesh_index < 0 || size_t(mesh_index) >= model.meshes.size())
        return gltf_error(path,
                          fmt::format("node refers to mesh {} which does not exist", mesh_index));
    const glm::dmat3 nxf = glm::transpose(glm::inverse(glm::dmat3(xf)));
    for (const auto& prim : model.meshes[mesh_index].primitives) {
        if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1)
            continue;  // points/lines: not a surface
        auto pos_it = prim.attributes.find("POSITION");
        if (pos_it == prim.attributes.end())
            return gltf_error(path, "a triangle primitive has no POSITION");
        HS_ASSIGN_OR_RETURN(
            auto pos, read_accessor(model, pos_it->second, TINYGLTF_TYPE_VEC3, path, "POSITION"));
        const size_t nv = pos.size() / 3;
        std::vector<double> nrm, uv;
        if (auto it = prim.attributes.find("NORMAL"); it != prim.attributes.end()) {
            HS_ASSIGN_OR_RETURN(
                nrm, read_accessor(model, it->second, TINYGLTF_TYPE_VEC3, path, "NORMAL"));
            if (nrm.size() != pos.size())
                return gltf_error(path, "NORMAL and POSITION counts differ");
        }
        if (auto it = prim.attributes.find("TEXCOORD_0"); it != prim.attributes.end()) {
            HS_ASSIGN_OR_RETURN(
                uv, read_accessor(model, it->second, TINYGLTF_TYPE_VEC2, path, "TEXCOORD_0"));
            if (uv.size() / 2 != nv)
                return gltf_error(path, "TEXCOORD_0 and POSITION counts differ");
        }
        std::vector<double> tan;
        if (auto it = prim.attributes.find("TANGENT"); it != prim.attributes.end()) {
            HS_ASSIGN_OR_RETURN(
                tan, read_accessor(model, it->second, TINYGLTF_TYPE_VEC4, path, "TANGENT"));
            if (tan.size() / 4 != nv)
                return gltf_error(path, "TANGENT and POSITION counts differ");
        }
        std::vector<double> idx;
        if (prim.indices >= 0) {
            HS_ASSIGN_OR_RETURN(
                idx, read_accessor(model, prim.indices, TINYGLTF_TYPE_SCALAR, path, "indices"));
        } else {
            for (size_t i = 0; i < nv; ++i) idx.push_back(double(i));
        }
        const uint32_t base = uint32_t(out.positions.size());
        const bool have_normals = !nrm.empty() && (out.normals.size() == out.positions.size());
        for (size_t i = 0; i < nv; ++i) {
            glm::dvec3 p =
                glm::dvec3(xf * glm::dvec4(pos[3 * i], pos[3 * i + 1], pos[3 * i + 2], 1.0));
            out.positions.push_back(glm::vec3(p));
            if (have_normals) {
                glm::dvec3 n = nxf * glm::dvec3(nrm[3 * i], nrm[3 * i + 1], nrm[3 * i + 2]);
                out.normals.push_back(glm::vec3(n));
            }
            out.uvs.push_back(uv.empty() ? glm::vec2(0) : glm::vec2(uv[2 * i], uv[2 * i + 1]));
            glm::dvec3 t = tan.empty() ? glm::dvec3(1, 0, 0)
                                       : glm::dvec3(tan[4 * i], tan[4 * i + 1], tan[4 * i + 2]);
            out.tangents.push_back(glm::vec3(glm::dmat3(xf) * t));
        }
        if (!have_normals)
            out.normals.clear();  // computed for the whole mesh by clean_mesh
        for (double v : idx) {
            if (v >= nv)
                return gltf_error(path,
                                  fmt::format("index {} is out of range ({} vertices)", v, nv));
            out.indices.push_back(base + uint32_t(v));
        }
    }
    return {};
}

Result<void> visit(const tinygltf::Model& model, int node, const glm::dmat4& parent,
                   const std::string& path, Mesh& out, int depth) {
    if (node < 0 || size_t(node) >= model.nodes.size())
        return gltf_error(path, fmt::format("node {} does not exist", node));
    if (depth > 64)
        return gltf_error(path, "node hierarchy deeper than 64 (a cycle?)");
    const auto& n = model.nodes[node];
    glm::dmat4 xf = parent * node_matrix(n);
    if (n.mesh >= 0)
        HS_TRY(append_mesh(model, n.mesh, xf, path, out));
    for (int c : n.children) HS_TRY(visit(model, c, xf, path, out, depth + 1));
    return {};
}

}  // namespace

Result<Mesh> load_gltf_mesh(const std::string& path, double scale, glm::dvec3 translation) {
    if (!std::filesystem::exists(path))
        return make_error(ErrorCode::kNotFound, fmt::format("{}: glTF file does not exist", path));
    tinygltf::TinyGLTF loader;
    tinygltf::Model model;
    std::string err, warn;
    bool ok = false;
    try {
        ok = path.ends_with(".glb") ? loader.LoadBinaryFromFile(&model, &err, &warn, path)
                                    : loader.LoadASCIIFromFile(&model, &err, &warn, path);
    } catch (const std::exception& e) {
        return gltf_error(path, fmt::format("malformed glTF: {}", e.what()));
    }
    if (!ok)
        return gltf_error(path,
                          fmt::format("malformed glTF: {}", err.empty() ? "unknown error" : err));
    glm::dmat4 root = glm::translate(glm::dmat4(1.0), translation) *
                      glm::scale(glm::dmat4(1.0), glm::dvec3(scale));
    Mesh out;
    if (!model.scenes.empty()) {
        int si = model.defaultScene >= 0 && size_t(model.defaultScene) < model.scenes.size()
                     ? model.defaultScene
                     : 0;
        for (int n : model.scenes[si].nodes) HS_TRY(visit(model, n, root, path, out, 0));
    } else {
        for (size_t m = 0; m < model.meshes.size(); ++m)
            HS_TRY(append_mesh(model, int(m), root, path, out));
    }
    if (out.positions.empty())
        return gltf_error(path, "the file holds no triangle mesh");
    return out;
}

}  // namespace hs::scene
