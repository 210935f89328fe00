// Occlusion and first-hit queries on a triangle soup with Embree 4, called
// from C++ threads. The Embree library is the one the embreex wheel ships; it
// is opened at run time (dlopen), so building voxgi needs no Embree headers
// and the Python and C++ paths trace against the same Embree.
#pragma once

#include <cstdint>
#include <memory>
#include <string>

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
    // `library`: path of libembree4; `tris`: (n_tris, 3, 3) float32 corners.
    // Throws std::runtime_error naming the library or Embree's error, or the
    // version when the library is not Embree 4.
    RayScene(const std::string& library, const float* tris, int64_t n_tris);
    ~RayScene();
    RayScene(const RayScene&) = delete;
    RayScene& operator=(const RayScene&) = delete;

    int64_t triangle_count() const { return n_tris_; }
    // The library's version, 10000 major + 100 minor + patch.
    int64_t embree_version() const { return version_; }

    // One ray: true when a triangle lies on [org, org + tfar·dir).
    bool occluded(const float org[3], const float dir[3], float tfar) const;
    // One ray: the first triangle hit (-1: none), with its barycentrics u, v
    // and distance t when the pointers are not null.
    int32_t intersect(const float org[3], const float dir[3], float* u, float* v, float* t) const;

    // Batches, split over `threads` (the caller's thread is one of them).
    void occluded(const float* org, const float* dir, const float* tfar, int64_t n, uint8_t* out,
                  int threads, const StopCheck& stop) const;
    void intersect(const float* org, const float* dir, int64_t n, int32_t* prim, float* u, float* v,
                   int threads, const StopCheck& stop) const;

   private:
    const EmbreeApi* api_ = nullptr;
    void* device_ = nullptr;
    void* scene_ = nullptr;
    int64_t n_tris_ = 0;
    int64_t version_ = 0;
};

}  // namespace voxgi
