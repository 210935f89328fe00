// Occlusion and first-hit queries on a triangle soup with Embree 4, called
// from C++ threads. Triangles may be transmitting sheets (glass,
// docs/design.md §13): light crosses them straight, scaled by their RGB
// transmittance; the queries see through them and report the product. The Embree library is the one
// the embreex wheel ships; it is opened at run time (dlopen), so building voxgi needs no Embree
// headers and the Python and C++ paths trace against the same Embree.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "util/parallel.h"

namespace voxgi {

struct EmbreeApi;  // the library's entry points (ray_scene.cpp)

// The major version of Embree whose ABI RayScene declares.
constexpr int64_t kEmbreeMajor = 4;

// "major.minor.patch" of a version number as Embree reports it (10000 major +
// 100 minor + patch).
std::string version_string(int64_t version);

class RayScene {
   public:
    // `library`: path of libembree4; `tris`: (n_tris, 3, 3) float32 corners;
    // `transmittance`: (n_tris, 3) per triangle, or null (every triangle
    // opaque); a triangle with a channel above 0 is a sheet. Throws
    // std::runtime_error naming the library or Embree's error, or the
    // version when the library is not Embree 4.
    RayScene(const std::string& library, const float* tris, int64_t n_tris,
             const float* transmittance = nullptr);
    ~RayScene();
    RayScene(const RayScene&) = delete;
    RayScene& operator=(const RayScene&) = delete;

    int64_t triangle_count() const { return n_tris_; }
    // How many triangles have a reversed twin (see intersect).
    int64_t twin_count() const { return n_twins_; }
    // The library's version, 10000 major + 100 minor + patch.
    int64_t embree_version() const { return version_; }

    // Whether any triangle is a sheet.
    bool has_sheets() const { return sheet_scene_ != nullptr; }

    // One ray: true when no light passes [org, org + tfar·dir): an opaque
    // triangle lies on it, or the sheets on it let nothing through.
    // Otherwise, with `through` not null, the product of their
    // transmittances there ({1, 1, 1} without sheets).
    bool occluded(const float org[3], const float dir[3], float tfar,
                  float* through = nullptr) const;
    // One ray: the first opaque triangle hit (-1: none), with its
    // barycentrics u, v and distance t when the pointers are not null, and
    // with `through` the product of the sheets' transmittances before it.
    // Of two opaque triangles with the same corners in reverse order (a
    // one-sided surface and its back, as a file's two-sided emitter loads),
    // the one whose front the ray meets.
    int32_t intersect(const float org[3], const float dir[3], float* u, float* v, float* t,
                      float* through = nullptr) const;

    // Batches, split over `threads` (the caller's thread is one of them).
    // `through` (n, 3) or null as above.
    void occluded(const float* org, const float* dir, const float* tfar, int64_t n, uint8_t* out,
                  float* through, int threads, const StopCheck& stop) const;
    void intersect(const float* org, const float* dir, int64_t n, int32_t* prim, float* u, float* v,
                   float* through, int threads, const StopCheck& stop) const;

   private:
    // Multiplies `through` by the transmittance of each sheet on [0, tfar).
    void cross_sheets(const float org[3], const float dir[3], float tfar, float* through) const;
    void* build(const float* tris, const std::vector<uint32_t>* pick) const;
    void find_twins(const float* tris, const float* transmittance);
    // The triangle a hit on `prim` (a scene index) stands for, its
    // barycentrics moved along: prim's reversed twin where the ray meets
    // prim's back.
    int32_t facing(int32_t prim, const float dir[3], float* u, float* v) const;

    const EmbreeApi* api_ = nullptr;
    void* device_ = nullptr;
    void* scene_ = nullptr;        // the opaque triangles
    void* sheet_scene_ = nullptr;  // the sheets, or null where there are none
    // With sheets: the scene's triangle index of each of scene_'s triangles
    // and each sheet's RGB transmittance in sheet_scene_'s order.
    std::vector<uint32_t> opaque_index_;
    std::vector<float> sheet_transmittance_;
    // Per triangle (empty where none has one): its reversed twin, -1 for
    // none, the twin's corners 1 and 2 as corners of this triangle, and this
    // triangle's normal by its winding.
    struct Twin {
        int32_t tri = -1;
        uint8_t c1 = 0, c2 = 0;
        float n[3] = {0.f, 0.f, 0.f};
    };
    std::vector<Twin> twins_;
    int64_t n_twins_ = 0;
    int64_t n_tris_ = 0;
    int64_t version_ = 0;
};

}  // namespace voxgi
