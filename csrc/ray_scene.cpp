#include "ray_scene.h"

#ifndef _WIN32
#include <dlfcn.h>
#endif

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <limits>
#include <map>
#include <mutex>
#include <stdexcept>

namespace voxgi {

namespace {

// The few parts of Embree 4's C interface used here, declared from its
// documented ABI; the values are those of rtcore_*.h.
constexpr unsigned kInvalidId = ~0u;
constexpr int kGeometryTriangle = 0;
constexpr int kBufferIndex = 0;
constexpr int kBufferVertex = 1;
constexpr int kFormatUint3 = 0x5003;
constexpr int kFormatFloat3 = 0x9003;
constexpr int kSceneFlagRobust = 1 << 2;
constexpr int kDevicePropertyVersion = 0;  // RTC_DEVICE_PROPERTY_VERSION: 10000 major + ...

struct alignas(16) Ray {
    float org_x, org_y, org_z, tnear;
    float dir_x, dir_y, dir_z, time;
    float tfar;
    unsigned mask, id, flags;
};

struct alignas(16) Hit {
    float ng_x, ng_y, ng_z, u, v;
    unsigned prim_id, geom_id;
    unsigned inst_id[1];
};

// A ray and its hit, with room after the hit for the per-instance-level
// fields a build of Embree may append (more instance levels, instance
// primitive ids): the library writes them, and they land here.
struct alignas(16) RayHit {
    Ray ray;
    Hit hit;
    unsigned char spare[64];
};

Ray make_ray(const float o[3], const float d[3], float tfar) {
    Ray r;
    r.org_x = o[0];
    r.org_y = o[1];
    r.org_z = o[2];
    r.tnear = 0.0f;
    r.dir_x = d[0];
    r.dir_y = d[1];
    r.dir_z = d[2];
    r.time = 0.0f;
    r.tfar = tfar;
    r.mask = ~0u;
    r.id = 0;
    r.flags = 0;
    return r;
}

}  // namespace

struct EmbreeApi {
    void* (*new_device)(const char*);
    void (*release_device)(void*);
    int (*get_device_error)(void*);
    void* (*new_scene)(void*);
    void (*release_scene)(void*);
    void (*set_scene_flags)(void*, int);
    void (*commit_scene)(void*);
    void* (*new_geometry)(void*, int);
    void* (*set_new_geometry_buffer)(void*, int, unsigned, int, size_t, size_t);
    void (*commit_geometry)(void*);
    unsigned (*attach_geometry)(void*, void*);
    void (*release_geometry)(void*);
    void (*intersect1)(void*, RayHit*, void*);
    void (*occluded1)(void*, Ray*, void*);
    ptrdiff_t (*get_device_property)(void*, int);
};

namespace {

#ifdef _WIN32
// Windows builds trace through embreex's Python calls (voxgi.rays finds no
// library to hand over there); a RayScene cannot be made.
void* dlopen(const char*, int) { return nullptr; }
void* dlsym(void*, const char*) { return nullptr; }
const char* dlerror() { return "run-time loading of Embree is not supported on Windows"; }
constexpr int RTLD_NOW = 0, RTLD_LOCAL = 0;
#endif

template <class F>
void bind(void* lib, const std::string& path, const char* name, F& fn) {
    void* sym = dlsym(lib, name);
    if (sym == nullptr)
        throw std::runtime_error(path + " has no symbol " + name + ": not an Embree 4 library");
    fn = reinterpret_cast<F>(sym);
}

// Opened once per path and kept for the life of the process: scenes made
// from it may outlive any one Python object.
const EmbreeApi* load_embree(const std::string& path) {
    static std::mutex mutex;
    static std::map<std::string, EmbreeApi> loaded;
    std::lock_guard<std::mutex> lock(mutex);
    auto it = loaded.find(path);
    if (it != loaded.end()) return &it->second;
    void* lib = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (lib == nullptr) {
        const char* why = dlerror();
        throw std::runtime_error("cannot open the Embree library " + path + ": " +
                                 (why ? why : "unknown error"));
    }
    EmbreeApi api{};
    bind(lib, path, "rtcNewDevice", api.new_device);
    bind(lib, path, "rtcReleaseDevice", api.release_device);
    bind(lib, path, "rtcGetDeviceError", api.get_device_error);
    bind(lib, path, "rtcNewScene", api.new_scene);
    bind(lib, path, "rtcReleaseScene", api.release_scene);
    bind(lib, path, "rtcSetSceneFlags", api.set_scene_flags);
    bind(lib, path, "rtcCommitScene", api.commit_scene);
    bind(lib, path, "rtcNewGeometry", api.new_geometry);
    bind(lib, path, "rtcSetNewGeometryBuffer", api.set_new_geometry_buffer);
    bind(lib, path, "rtcCommitGeometry", api.commit_geometry);
    bind(lib, path, "rtcAttachGeometry", api.attach_geometry);
    bind(lib, path, "rtcReleaseGeometry", api.release_geometry);
    bind(lib, path, "rtcIntersect1", api.intersect1);
    bind(lib, path, "rtcOccluded1", api.occluded1);
    bind(lib, path, "rtcGetDeviceProperty", api.get_device_property);
    return &loaded.emplace(path, api).first->second;
}

constexpr int64_t kBatch = 4096;  // rays per task of a batch query

}  // namespace

std::string version_string(int64_t v) {
    return std::to_string(v / 10000) + "." + std::to_string(v / 100 % 100) + "." +
           std::to_string(v % 100);
}

RayScene::RayScene(const std::string& library, const float* tris, int64_t n_tris,
                   const float* transmittance)
    : api_(load_embree(library)), n_tris_(n_tris) {
    if (n_tris < 0 || n_tris >= static_cast<int64_t>(kInvalidId) / 3)
        throw std::invalid_argument("RayScene: triangle count out of range");
    // Sheets go in a scene of their own: the opaque rays stay Embree's own
    // queries, and a scene without sheets builds no second scene at all.
    std::vector<uint32_t> sheets;
    if (transmittance) {
        for (int64_t i = 0; i < n_tris; ++i) {
            const float* T = transmittance + 3 * i;
            if (T[0] > 0.f || T[1] > 0.f || T[2] > 0.f) {
                sheets.push_back(uint32_t(i));
            } else {
                opaque_index_.push_back(uint32_t(i));
            }
        }
        if (sheets.empty()) opaque_index_.clear();
    }
    device_ = api_->new_device(nullptr);
    if (device_ == nullptr) throw std::runtime_error("Embree could not create a device");
    // The ray and hit layouts above are Embree 4's; another major version
    // would read and write them wrongly.
    version_ = int64_t(api_->get_device_property(device_, kDevicePropertyVersion));
    if (version_ / 10000 != kEmbreeMajor) {
        api_->release_device(device_);
        throw std::runtime_error(library + " is Embree " + version_string(version_) +
                                 ", not the Embree 4 whose ray layout voxgi uses");
    }
    try {
        scene_ = build(tris, sheets.empty() ? nullptr : &opaque_index_);
        find_twins(tris, sheets.empty() ? nullptr : transmittance);
        if (!sheets.empty()) {
            sheet_scene_ = build(tris, &sheets);
            sheet_transmittance_.resize(3 * sheets.size());
            for (size_t k = 0; k < sheets.size(); ++k)
                for (int c = 0; c < 3; ++c)
                    sheet_transmittance_[3 * k + c] =
                        std::clamp(transmittance[3 * int64_t(sheets[k]) + c], 0.f, 1.f);
        }
    } catch (...) {
        if (scene_) api_->release_scene(scene_);
        api_->release_device(device_);
        throw;
    }
}

// Two coincident faces of opposite winding are one surface seen from two
// sides (a one-sided emitter and the black or reflecting back that a file's
// two-sided emitter loads as, docs/design.md §12). Embree meets either at
// the same distance, so without this half the rays that reach the emitter
// from its front would read its back, black. The twins are found by their
// corners, exactly: each triangle's corners rotated to start at the least
// (in coordinate order), forwards and reversed, sorted and matched.
void RayScene::find_twins(const float* tris, const float* transmittance) {
    using Key = std::array<float, 9>;
    auto corner_less = [](const float* a, const float* b) {
        return std::lexicographical_compare(a, a + 3, b, b + 3);
    };
    auto key = [&](int64_t i, bool reversed) {
        const float* t = tris + 9 * i;
        const float* c[3] = {t, reversed ? t + 6 : t + 3, reversed ? t + 3 : t + 6};
        int first = 0;
        for (int k = 1; k < 3; ++k)
            if (corner_less(c[k], c[first])) first = k;
        Key out;
        for (int k = 0; k < 3; ++k) std::memcpy(out.data() + 3 * k, c[(first + k) % 3], 12);
        return out;
    };
    auto opaque = [&](int64_t i) {
        if (!transmittance) return true;
        const float* T = transmittance + 3 * i;
        return !(T[0] > 0.f || T[1] > 0.f || T[2] > 0.f);
    };
    auto degenerate = [&](int64_t i) {
        const float* t = tris + 9 * i;
        return std::equal(t, t + 3, t + 3) || std::equal(t, t + 3, t + 6) ||
               std::equal(t + 3, t + 6, t + 6);
    };
    std::vector<std::pair<Key, int32_t>> fwd;
    for (int64_t i = 0; i < n_tris_; ++i)
        if (opaque(i) && !degenerate(i)) fwd.emplace_back(key(i, false), int32_t(i));
    std::sort(fwd.begin(), fwd.end());
    for (const auto& [k, i] : fwd) {
        const Key want = key(i, true);
        auto it = std::lower_bound(fwd.begin(), fwd.end(), std::make_pair(want, int32_t(-1)));
        if (it == fwd.end() || it->first != want) continue;
        if (twins_.empty()) twins_.resize(size_t(n_tris_));
        Twin& w = twins_[size_t(i)];
        w.tri = it->second;
        const float *p = tris + 9 * int64_t(i), *q = tris + 9 * int64_t(w.tri);
        auto corner_of_p = [&](const float* c) {
            for (int k = 0; k < 3; ++k)
                if (std::equal(c, c + 3, p + 3 * k)) return uint8_t(k);
            return uint8_t(0);
        };
        w.c1 = corner_of_p(q + 3);
        w.c2 = corner_of_p(q + 6);
        const double e1[3] = {p[3] - p[0], p[4] - p[1], p[5] - p[2]};
        const double e2[3] = {p[6] - p[0], p[7] - p[1], p[8] - p[2]};
        w.n[0] = float(e1[1] * e2[2] - e1[2] * e2[1]);
        w.n[1] = float(e1[2] * e2[0] - e1[0] * e2[2]);
        w.n[2] = float(e1[0] * e2[1] - e1[1] * e2[0]);
        ++n_twins_;
    }
}

int32_t RayScene::facing(int32_t prim, const float dir[3], float* u, float* v) const {
    if (twins_.empty()) return prim;
    const Twin& w = twins_[size_t(prim)];
    if (w.tri < 0 || !(dir[0] * w.n[0] + dir[1] * w.n[1] + dir[2] * w.n[2] > 0.f)) return prim;
    if (u && v) {
        const float b[3] = {1.f - *u - *v, *u, *v};
        *u = b[w.c1];
        *v = b[w.c2];
    }
    return w.tri;
}

// An Embree scene of the triangles `pick` lists (null: all of them).
void* RayScene::build(const float* tris, const std::vector<uint32_t>* pick) const {
    const int64_t n = pick ? int64_t(pick->size()) : n_tris_;
    void* scene = api_->new_scene(device_);
    api_->set_scene_flags(scene, kSceneFlagRobust);
    if (n > 0) {
        void* geom = api_->new_geometry(device_, kGeometryTriangle);
        auto* v = static_cast<float*>(api_->set_new_geometry_buffer(
            geom, kBufferVertex, 0, kFormatFloat3, 3 * sizeof(float), 3 * n));
        auto* idx = static_cast<unsigned*>(api_->set_new_geometry_buffer(
            geom, kBufferIndex, 0, kFormatUint3, 3 * sizeof(unsigned), n));
        if (v == nullptr || idx == nullptr) {
            api_->release_geometry(geom);
            api_->release_scene(scene);
            throw std::runtime_error("Embree could not allocate " + std::to_string(n) +
                                     " triangles");
        }
        if (pick) {
            for (int64_t k = 0; k < n; ++k)
                std::memcpy(v + 9 * k, tris + 9 * int64_t((*pick)[k]), sizeof(float) * 9);
        } else {
            std::memcpy(v, tris, sizeof(float) * 9 * n);
        }
        for (int64_t i = 0; i < 3 * n; ++i) idx[i] = static_cast<unsigned>(i);
        api_->commit_geometry(geom);
        api_->attach_geometry(scene, geom);
        api_->release_geometry(geom);
    }
    api_->commit_scene(scene);
    if (int err = api_->get_device_error(device_); err != 0) {
        api_->release_scene(scene);
        throw std::runtime_error("Embree failed to build the scene (error " + std::to_string(err) +
                                 ")");
    }
    return scene;
}

RayScene::~RayScene() {
    if (sheet_scene_) api_->release_scene(sheet_scene_);
    if (scene_) api_->release_scene(scene_);
    if (device_) api_->release_device(device_);
}

namespace {

// Sheets met along one ray, at most: a ray through more (a stack of panes)
// keeps the product of these.
constexpr int kMaxSheets = 64;

}  // namespace

void RayScene::cross_sheets(const float org[3], const float dir[3], float tfar,
                            float* through) const {
    // The sheets one after another, each search starting just past the last
    // hit: Embree reports the nearest hit beyond tnear, so each sheet counts
    // once, and two triangles meeting at an edge the ray passes count once.
    float tnear = 0.0f;
    for (int k = 0; k < kMaxSheets; ++k) {
        RayHit rh;
        rh.ray = make_ray(org, dir, tfar);
        rh.ray.tnear = tnear;
        rh.hit.geom_id = kInvalidId;
        rh.hit.prim_id = kInvalidId;
        rh.hit.inst_id[0] = kInvalidId;
        api_->intersect1(sheet_scene_, &rh, nullptr);
        if (rh.hit.geom_id == kInvalidId) return;
        const float* T = sheet_transmittance_.data() + 3 * size_t(rh.hit.prim_id);
        for (int c = 0; c < 3; ++c) through[c] *= T[c];
        if (!(through[0] > 0.f || through[1] > 0.f || through[2] > 0.f)) return;
        const float t = rh.ray.tfar;
        tnear = t + std::max(1e-6f * t, 1e-7f);
        if (!(tnear < tfar)) return;
    }
}

bool RayScene::occluded(const float org[3], const float dir[3], float tfar, float* through) const {
    if (through) through[0] = through[1] = through[2] = 1.0f;
    if (!(tfar > 0.0f)) return false;  // an empty segment (or NaN) meets nothing
    Ray r = make_ray(org, dir, tfar);
    api_->occluded1(scene_, &r, nullptr);
    if (r.tfar < 0.0f) {  // -inf when something was found
        if (through) through[0] = through[1] = through[2] = 0.0f;
        return true;
    }
    if (!sheet_scene_) return false;
    float T[3] = {1.0f, 1.0f, 1.0f};
    cross_sheets(org, dir, tfar, T);
    if (through) std::memcpy(through, T, sizeof T);
    return !(T[0] > 0.f || T[1] > 0.f || T[2] > 0.f);
}

int32_t RayScene::intersect(const float org[3], const float dir[3], float* u, float* v, float* t,
                            float* through) const {
    RayHit rh;
    rh.ray = make_ray(org, dir, std::numeric_limits<float>::infinity());
    rh.hit.geom_id = kInvalidId;
    rh.hit.prim_id = kInvalidId;
    rh.hit.inst_id[0] = kInvalidId;
    api_->intersect1(scene_, &rh, nullptr);
    const bool hit = rh.hit.geom_id != kInvalidId;
    if (u) *u = hit ? rh.hit.u : 0.0f;
    if (v) *v = hit ? rh.hit.v : 0.0f;
    if (t) *t = hit ? rh.ray.tfar : std::numeric_limits<float>::infinity();
    if (through) {
        through[0] = through[1] = through[2] = 1.0f;
        if (sheet_scene_) cross_sheets(org, dir, rh.ray.tfar, through);
    }
    if (!hit) return -1;
    const uint32_t prim = opaque_index_.empty() ? rh.hit.prim_id : opaque_index_[rh.hit.prim_id];
    return facing(static_cast<int32_t>(prim), dir, u, v);
}

void RayScene::occluded(const float* org, const float* dir, const float* tfar, int64_t n,
                        uint8_t* out, float* through, int threads, const StopCheck& stop) const {
    const int64_t tasks = (n + kBatch - 1) / kBatch;
    parallel_for(tasks, threads, stop, [&](int64_t task, int) {
        const int64_t end = std::min(n, (task + 1) * kBatch);
        for (int64_t i = task * kBatch; i < end; ++i)
            out[i] =
                occluded(org + 3 * i, dir + 3 * i, tfar[i], through ? through + 3 * i : nullptr)
                    ? 1
                    : 0;
    });
}

void RayScene::intersect(const float* org, const float* dir, int64_t n, int32_t* prim, float* u,
                         float* v, float* through, int threads, const StopCheck& stop) const {
    const int64_t tasks = (n + kBatch - 1) / kBatch;
    parallel_for(tasks, threads, stop, [&](int64_t task, int) {
        const int64_t end = std::min(n, (task + 1) * kBatch);
        for (int64_t i = task * kBatch; i < end; ++i)
            prim[i] = intersect(org + 3 * i, dir + 3 * i, u ? u + i : nullptr, v ? v + i : nullptr,
                                nullptr, through ? through + 3 * i : nullptr);
    });
}

}  // namespace voxgi
