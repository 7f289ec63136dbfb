// The only file that sees tinygltf. Every accessor is bounds-checked before it is read, so a
// malformed file is an error naming the file and the problem, never a crash.
#include <cctype>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <optional>

#include <fmt/format.h>
#include <tiny_gltf.h>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>

#include "scene/assets.hpp"
#include "scene/json_limits.hpp"
#include "scene/mesh.hpp"

namespace hs::scene {

namespace {

namespace fs = std::filesystem;

// Nodes visited while walking the scene graph: a node may be the child of many, so a small file
// can name exponentially many instances.
constexpr uint64_t kMaxNodeVisits = 65'536;

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

// Where tinygltf may read external buffers and images from: inside the asset root only.
struct FsContext {
    fs::path asset_root;
    std::string base_dir;          // the glTF's folder, as tinygltf joins it before a URI
    std::optional<Error> refused;  // the first external file refused, in the glTF's words
};

// Says yes to every path, so that fs_read is what decides and words the refusal.
bool fs_exists(const std::string& abs_filename, void*) {
    return !abs_filename.empty();
}

std::string fs_expand(const std::string& path, void*) {
    return path;  // no "~" or environment expansion: a file names itself
}

bool fs_read(std::vector<unsigned char>* out, std::string* err, const std::string& filepath,
             void* user) {
    auto* ctx = static_cast<FsContext*>(user);
    auto real = resolve_asset(filepath, {}, ctx->asset_root);
    if (!real) {
        // Say it with the URI as the glTF wrote it (tinygltf prefixes the glTF's folder).
        std::string_view uri = filepath;
        if (uri.starts_with(ctx->base_dir + "/"))
            uri.remove_prefix(ctx->base_dir.size() + 1);
        if (!ctx->refused)
            ctx->refused = resolve_asset(uri, ctx->base_dir, ctx->asset_root).error();
        if (err)
            *err += "refused\n";
        return false;
    }
    std::ifstream in(*real, std::ios::binary);
    out->assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    if (!in.good() && !in.eof()) {
        if (err)
            *err += fmt::format("{}: read error\n", quote_text(filepath));
        return false;
    }
    return true;
}

bool fs_write(std::string* err, const std::string&, const std::vector<unsigned char>&, void*) {
    if (err)
        *err += "writing files is not allowed\n";
    return false;
}

// Images are not used (the albedo texture comes from the scene): skip decoding them.
bool skip_image(tinygltf::Image*, const int, std::string*, std::string*, int, int,
                const unsigned char*, int, void*) {
    return true;
}

// Counts what the build pass would produce, without reading any vertex, and refuses a file
// over the limits before anything large is allocated.
struct Budget {
    uint64_t max_triangles = 0;
    uint64_t triangles = 0;
    uint64_t vertices = 0;
    uint64_t visits = 0;
};

Result<void> count_mesh(const tinygltf::Model& model, int mesh_index, const std::string& path,
                        Budget& b) {
    if (mesh_index < 0 || size_t(mesh_index) >= model.meshes.size())
        return {};  // reported by the build pass
    for (const auto& prim : model.meshes[mesh_index].primitives) {
        if (prim.mode != TINYGLTF_MODE_TRIANGLES && prim.mode != -1)
            continue;
        auto pos = prim.attributes.find("POSITION");
        if (pos == prim.attributes.end() || pos->second < 0 ||
            size_t(pos->second) >= model.accessors.size())
            continue;
        const uint64_t nv = model.accessors[pos->second].count;
        uint64_t ni = nv;
        if (prim.indices >= 0 && size_t(prim.indices) < model.accessors.size())
            ni = model.accessors[prim.indices].count;
        b.vertices += nv;
        b.triangles += ni / 3;
        if (b.triangles > b.max_triangles)
            return gltf_error(
                path, fmt::format("more than {} triangles (the triangle limit)", b.max_triangles));
        if (b.vertices > 3 * b.max_triangles + 3)
            return gltf_error(path, fmt::format("more than {} vertices (3 x the triangle limit)",
                                                3 * b.max_triangles + 3));
    }
    return {};
}

Result<void> count_visit(const tinygltf::Model& model, int node, const std::string& path, int depth,
                         Budget& b) {
    if (node < 0 || size_t(node) >= model.nodes.size() || depth > 64)
        return {};  // reported by the build pass
    if (++b.visits > kMaxNodeVisits)
        return gltf_error(path, fmt::format("the node hierarchy names more than {} node "
                                            "instances",
                                            kMaxNodeVisits));
    const auto& n = model.nodes[node];
    if (n.mesh >= 0)
        HS_TRY(count_mesh(model, n.mesh, path, b));
    for (int c : n.children) HS_TRY(count_visit(model, c, path, depth + 1, b));
    return {};
}

// The JSON part of a .gltf, or of a .glb's first chunk; empty when the container is malformed
// (tinygltf then says what is wrong).
std::string_view json_part(const std::vector<unsigned char>& bytes, bool binary) {
    const char* data = reinterpret_cast<const char*>(bytes.data());
    if (!binary)
        return {data, bytes.size()};
    if (bytes.size() < 20)
        return {};
    uint32_t length = 0, type = 0;
    std::memcpy(&length, data + 12, 4);
    std::memcpy(&type, data + 16, 4);
    if (type != 0x4E4F534Au || length > bytes.size() - 20)
        return {};
    return {data + 20, length};
}

// The triangles of the model's default scene (or of every mesh when it has no scene), placed by
// `info`, within its triangle budget.
Result<Mesh> mesh_of(const tinygltf::Model& model, const GltfLoadInfo& info,
                     const std::string& path) {
    glm::dmat4 root = glm::translate(glm::dmat4(1.0), info.translation) *
                      glm::scale(glm::dmat4(1.0), glm::dvec3(info.scale));
    Budget budget;
    budget.max_triangles = info.max_triangles;
    int scene_index = -1;
    if (!model.scenes.empty()) {
        scene_index = model.defaultScene >= 0 && size_t(model.defaultScene) < model.scenes.size()
                          ? model.defaultScene
                          : 0;
        for (int n : model.scenes[scene_index].nodes)
            HS_TRY(count_visit(model, n, path, 0, budget));
    } else {
        for (size_t m = 0; m < model.meshes.size(); ++m)
            HS_TRY(count_mesh(model, int(m), path, budget));
    }
    Mesh out;
    try {
        if (scene_index >= 0) {
            for (int n : model.scenes[scene_index].nodes)
                HS_TRY(visit(model, n, root, path, out, 0));
        } else {
            for (size_t m = 0; m < model.meshes.size(); ++m)
                HS_TRY(append_mesh(model, int(m), root, path, out));
        }
    } catch (const std::exception& e) {  // std::bad_alloc
        return gltf_error(path, fmt::format("could not build the mesh: {}", e.what()));
    }
    if (out.positions.empty())
        return gltf_error(path, "the file holds no triangle mesh");
    return out;
}

}  // namespace

Result<Mesh> load_gltf_mesh(const std::string& path, const GltfLoadInfo& info) {
    const fs::path folder =
        fs::path(path).parent_path().empty() ? fs::path(".") : fs::path(path).parent_path();
    FsContext ctx{info.asset_root.empty() ? folder : info.asset_root, {}, std::nullopt};
    // The file itself obeys the same rule as its buffers.
    auto real = resolve_asset(path, {}, ctx.asset_root);
    if (!real)
        return gltf_error(path, real.error().message);
    std::vector<unsigned char> bytes;
    {
        std::ifstream in(*real, std::ios::binary);
        bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
        if (!in.good() && !in.eof())
            return make_error(ErrorCode::kIo, fmt::format("{}: read error", path));
    }
    const bool binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
    // tinygltf turns JSON into its own values recursively (extras, extensions): refuse deep or
    // huge JSON before it sees it. Data URIs make long strings legitimate.
    JsonLimits limits;
    limits.max_bytes = kMaxAssetBytes;
    limits.max_elements = 1u << 20;
    limits.max_string_bytes = kMaxAssetBytes;
    if (std::string_view j = json_part(bytes, binary); !j.empty())
        if (auto checked = check_json_text(j, path, limits); !checked)
            return make_error(ErrorCode::kParse,
                              fmt::format("malformed glTF: {}", checked.error().message));

    tinygltf::TinyGLTF loader;
    loader.SetFsCallbacks(tinygltf::FsCallbacks{&fs_exists, &fs_expand, &fs_read, &fs_write, &ctx});
    loader.SetImageLoader(&skip_image, nullptr);
    tinygltf::Model model;
    std::string err, warn;
    bool ok = false;
    const std::string base_dir = real->parent_path().string();
    ctx.base_dir = base_dir;
    try {
        if (bytes.size() > std::numeric_limits<unsigned int>::max())
            return gltf_error(path, "the file is too large");
        ok = binary ? loader.LoadBinaryFromMemory(&model, &err, &warn, bytes.data(),
                                                  static_cast<unsigned int>(bytes.size()), base_dir)
                    : loader.LoadASCIIFromString(&model, &err, &warn,
                                                 reinterpret_cast<const char*>(bytes.data()),
                                                 static_cast<unsigned int>(bytes.size()), base_dir);
    } catch (const std::exception& e) {
        return gltf_error(path, fmt::format("malformed glTF: {}", e.what()));
    }
    if (!ok) {
        // A refused buffer: say so in the one wording. (A refused image is only a warning to
        // tinygltf, and images are not used.)
        if (ctx.refused)
            return gltf_error(path, fmt::format("external file {}", ctx.refused->message));
        while (!err.empty() && std::isspace(static_cast<unsigned char>(err.back()))) err.pop_back();
        return gltf_error(path,
                          fmt::format("malformed glTF: {}", err.empty() ? "unknown error" : err));
    }
    return mesh_of(model, info, path);
}

Result<Mesh> load_gltf_mesh(const std::string& path, double scale, glm::dvec3 translation) {
    GltfLoadInfo info;
    info.scale = scale;
    info.translation = translation;
    return load_gltf_mesh(path, info);
}

}  // namespace hs::scene
