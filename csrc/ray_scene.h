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

    const EmbreeApi* api_ = nullptr;
    void* device_ = nullptr;
    void* scene_ = nullptr;        // the opaque triangles
    void* sheet_scene_ = nullptr;  // the sheets, or null where there are none
    // With sheets: the scene's triangle index of each of scene_'s triangles
    // and each sheet's RGB transmittance in sheet_scene_'s order.
    std::vector<uint32_t> opaque_index_;
    std::vector<float> sheet_transmittance_;
    int64_t n_tris_ = 0;
    int64_t version_ = 0;
};

}  // namespace voxgi
