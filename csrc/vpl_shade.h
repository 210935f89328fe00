// VPL shading kernels for the anti-aliased display (docs/design.md §6).
//
// One frame shades P hit points with the same K virtual point lights (VPLs):
// vpl_light and gather_light make each pixel's shadow and gather rays, trace
// them in a RayScene as they are made and sum their light pixel by pixel,
// in a fixed order (the same image for any thread count).
// No pybind11 here: plain pointers and sizes.
#pragma once

#include <cstdint>

#include "environment.h"
#include "incidence_response.h"
#include "microfacet.h"
#include "ray_scene.h"
#include "record_lookup.h"
#include "texture.h"
#include "util/parallel.h"

namespace voxgi {

// Per-material shading parameters (M materials).
struct ShadeMaterials {
    int64_t count = 0;
    const float* albedo = nullptr;  // (M, 3) diffuse reflectance rho (Rd)
    const float* rs = nullptr;  // (M, 3) Ashikhmin-Shirley specular reflectance at normal incidence
    const float* nu = nullptr;  // (M,)   AS exponent along the tangent u
    const float* nv = nullptr;  // (M,)   AS exponent along the bitangent v
    const uint8_t* glossy = nullptr;  // (M,) 1 where the material has a specular layer
    // (M,) microfacet lobes (kind 0: the Ashikhmin-Shirley layer or none), or
    // null: no material has one (and no pixel pays for them)
    const MicrofacetLobe* lobe = nullptr;
    // (M, kIncidenceNodes, 3) or null: the solve's records as "pixels" of
    // gather_light, where f is multiplied by the material's incidence
    // response at the gather ray's cosine (incidence_response.h)
    const float* response = nullptr;
    // (hit_count,) or null: the lobes of the surfaces gather rays land on, by
    // object id (kind 0: none). The display's materials are its objects, so
    // there it is `lobe`; the solve's records as pixels are white
    // Lambertians whose rays land on the scene's objects.
    const MicrofacetLobe* hit_lobe = nullptr;
    int64_t hit_count = 0;
    // (hit_count,) or null: 1 where a gather ray that lands on the object's
    // surface reads the base's share of its record and follows the lobe's
    // specular reflection one bounce further (glossy_hit_radiance)
    const uint8_t* continue_lobe = nullptr;
    // (M, kIncidenceNodes, 3) or null: per material, the radiance its
    // diffuse base sends out at cosine mu over its mean (the base's
    // directional albedo by reciprocity, normalised), by which the base's
    // share of a glossy record's light leaves it towards a pixel whose gather
    // rays follow the lobes (given with continue_lobe)
    const float* base_out = nullptr;
};

// Whether the gather rays of a pixel of material m follow the lobes of the
// surfaces they land on: every shaded pixel, where continue_lobe is given. A
// diffuse pixel beside a mirror sees the mirror's reflection in its own
// direction, not the mirror's light spread evenly over the hemisphere
// (docs/design.md §14).
inline bool follows_lobes(const ShadeMaterials& mats, int32_t m) {
    return mats.continue_lobe && mats.hit_lobe && m >= 0 && m < mats.count;
}

// Hit points of one frame (P pixels).
struct ShadeHits {
    int64_t count = 0;
    const double* pos = nullptr;    // (P, 3) hit points on the surface
    const float* normal = nullptr;  // (P, 3) unit shading normal, on the viewer's side
    const float* ng = nullptr;      // (P, 3) unit geometric normal, on the viewer's side
    const float* wo = nullptr;      // (P, 3) unit direction from the hit point to the viewer
    const int32_t* material =
        nullptr;  // (P,) material index, or -1: not shaded (miss, black back side)
    const float* albedo = nullptr;  // (P, 3) each hit's diffuse albedo (its texture's), or
                                    // null: its material's
};

// The diffuse albedo of hit p (of material m): the hit's own, or its material's.
inline const float* hit_albedo(const ShadeHits& hits, const ShadeMaterials& mats, int64_t p,
                               int32_t m) {
    return hits.albedo ? hits.albedo + 3 * p : mats.albedo + 3 * int64_t(m);
}

// VPLs of one frame (K lights).
struct ShadeVPLs {
    int64_t count = 0;
    const double* pos = nullptr;    // (K, 3) point on the surface
    const float* normal = nullptr;  // (K, 3) unit normal
    const float* weight = nullptr;  // (K, 3) (TA_set / n_set) * B / pi: radiance times the
                                    // estimator weight; for an MIS VPL just its radiance B / pi
    const float* area = nullptr;    // (K,) area the record stands for (bounds the geometry term)
    const float* pa = nullptr;      // (K,) n_v x the VPL's area pdf (per unit area) for VPLs
                                    // combined with gather rays (balance heuristic), 0 for
                                    // the others; or null: none
    // (K, 3) or null: the share of its light a VPL brings a pixel whose
    // gather rays follow the lobes they land on (follows_lobes)
    const float* share = nullptr;
    // (K,) or null: each VPL's object (its material), for mats.base_out
    const int32_t* object = nullptr;
};

// Multiple importance sampling of each VPL set (emitters, the rest) between VPLs (n_v a
// frame, area pdf p_a(y) per unit area, so n_v p_a(y) in all) and n_g
// cosine-distributed gather rays per pixel (pdf n_g cos_x cos_y / (pi r²)
// per unit area). Balance heuristic: every sample of either kind adds
//     f L cos_x cos_y / (r² n_v p_a(y) + n_g cos_x cos_y / pi),
// which is at most pi f L / n_g: no 1/r² spike at contact, and no bias.
struct ShadeMIS {
    double n_gather = 0.0;  // gather rays per pixel per frame
};

// Scene triangles for the gather rays' hit points.
struct ShadeTriangles {
    int64_t count = 0;
    const double* v = nullptr;           // (F, 3, 3) corners
    const int32_t* object = nullptr;     // (F,)
    const uint8_t* two_sided = nullptr;  // (O,) per object
    // nullable: where a gather ray lands on a textured (non-emitting) object,
    // the record's light is taken times the texture there over the record's
    // albedo (the texture's detail within the record)
    const SurfaceTextures* textures = nullptr;
    // nullable (O,): 1 where the object emits
    const uint8_t* emits = nullptr;
    // A gather ray that lands nearer than this (scene units; 0: never) on a
    // diffuse object that does not emit continues one bounce there instead
    // of reading the record: a record averages its voxel, which a near hit
    // sees under a wide angle (a crease, a groove).
    double reach = 0.0;
    // The emitters' VPLs of the frame, for the direct light where such a ray
    // continues (one drawn uniformly, a shadow ray to it, MIS-combined with
    // the continued ray): their points, normals, radiance B / pi and area
    // densities p(y) in the emitters' table (none: the ray alone).
    int64_t emitter_count = 0;
    const double* emitter_pos = nullptr;
    const float* emitter_normal = nullptr;
    const float* emitter_radiance = nullptr;
    const float* emitter_density = nullptr;
    double emitter_per_set = 1.0;  // emitter VPLs a pixel sees (a record's pa over it: p(y))
};

// Per (pixel, VPL) pair the unoccluded contribution f(wi, wo) W_k G_bounded
// and, where it is non-zero, a shadow ray from the pixel's point (offset
// along its geometric normal by `eps`) to the VPL's point (offset along its
// normal by `eps`, stopping `eps` short), traced against `scene`; each pixel
// sums the contributions whose ray is free, in VPL order. With `pixel_set` (P,) (nullable),
// pixel p sees only VPLs set_start[s] .. set_start[s + 1] - 1 of set
// s = pixel_set[p] (interleaved sampling). Writes out (P, 3) and the number
// of shadow rays traced into *rays.
void vpl_light(const ShadeHits& hits, const ShadeMaterials& mats, const ShadeVPLs& vpls,
               const ShadeMIS& mis, double eps, const int32_t* pixel_set, const int64_t* set_start,
               const RayScene& scene, float* out, int64_t* rays, int threads,
               const StopCheck& stop);

// Gather rays: n_g cosine-distributed directions around the shading normal
// of each shaded pixel (material >= 0), stratified (n_g = m² strata: m in
// cos²θ x m in azimuth; any other n_g: n_g strata in cos²θ) and jittered
// with a hash of (seed, frame, pixel, k): the same for any thread count;
// each traced in `scene` as it is made. A ray that hits the black back of a
// one-sided surface adds nothing; one that hits a surface (emitters too:
// both VPL sets are MIS-combined with the gather rays) looks up the record
// at the hit point (same voxel or a neighbour, same side and object
// preferred, nearest centroid) and adds the MIS-weighted f L term, summed
// per pixel in ray order into out (P, 3). With `env`
// (nullable), a ray that meets nothing brings the environment's radiance
// L(w) over the combined density n_e p_e(w) + n_g cos / pi of the
// environment samples and the gather rays, summed per pixel after the
// records' light as light_accumulate sums. Writes the number of gather rays
// traced into *rays.
//
// With `transport`, each gather ray's outcome is written too, at
// p * n_gather + k for ray k of shaded pixel p (the rest left as they are):
// the record it read (grid order, -1: none) and the factor its radiance was
// multiplied by, so that the same rays can be applied to other radiances
// without tracing them again (the solve's traced passes, traced_transport.h).
//
// A ray that follows a lobe (ShadeMaterials::continue_lobe) is written as
// the record at the end of the lobe's ray, with the factor of that reading;
// the transport keeps no base share, so with a transport only objects
// whose records' share is zero (conductors) may continue. With `emitted`,
// each such ray also adds its factor times the emitted radiance of the
// record where it lands into emitted->out: the emitters' light seen in a
// lobe, which a pass of reflected light leaves out and the records' own
// direct light cannot see past the mirror.
struct GatherTransport {
    int32_t* record = nullptr;  // (P * n_gather,)
    float* weight = nullptr;    // (P * n_gather, 3)
};
struct LobeEmission {
    const float* radiance = nullptr;  // (N, 3) each record's emitted radiance, grid order
    float* out = nullptr;             // (P, 3), added into
};
void gather_light(const ShadeHits& hits, const ShadeMaterials& mats, const ShadeMIS& mis,
                  int n_gather, uint64_t seed, int64_t frame, double eps,
                  const ShadeTriangles& tris, const RecordGrid& grid, const EnvironmentMap* env,
                  const RayScene& scene, float* out, int64_t* rays, int threads,
                  const StopCheck& stop, const GatherTransport* transport = nullptr,
                  const LobeEmission* emitted = nullptr);

// Points on stacked sheets (RecordGrid::stacked 1): the VPLs drawn on them.
struct SheetPoints {
    int64_t count = 0;
    const double* pos = nullptr;      // (count, 3) on the sheet, in the grid's frame
    const float* normal = nullptr;    // (count, 3) unit normal of the record's side
    const int64_t* record = nullptr;  // (count,) the record each lies on (grid order)
};

// The radiance leaving each point of `at` (a diffuse sheet's: the same in
// every direction), into out (count, 3): the mean of `walks` walks from the
// point through its stack as gather_light's rays walk on from a sheet they
// land on (the emitters' light sampled at every bounce given the frame's
// emitter VPLs in tris), seeded by (seed, frame, point, walk). A VPL on a
// slat then carries the light leaving its own point, as the gather rays
// that land there read it, not its record's mean over the lit edge and the
// shaded middle. Writes the rays traced into *rays.
void sheet_radiance(const ShadeTriangles& tris, const RecordGrid& grid, const RayScene& scene,
                    double eps, const SheetPoints& at, int walks, uint64_t seed, int64_t frame,
                    float* out, int64_t* rays, int threads, const StopCheck& stop);

// Light arriving along known directions: point, spot and directional lights
// (one shadow ray each), environment samples and gather rays that leave the
// scene (docs/design.md §11). Rays are pixel-major, `ray_count` (P,) per
// pixel; each has a unit direction wi (R, 3) and an RGB weight (R, 3): the
// irradiance on a surface facing it for a delta light, or the radiance over
// its MIS-combined density for a sampled one. Adds f(wi, wo) max(0, n·wi)
// weight into out (P, 3) for each ray not occluded (`occluded` (R,) non-zero:
// blocked; null: none) whose wi lies above the geometric surface.
void light_accumulate(const ShadeHits& hits, const ShadeMaterials& mats, const int64_t* ray_count,
                      const float* ray_dir, const float* ray_weight, const uint8_t* occluded,
                      float* out, int threads, const StopCheck& stop);

// Primary hits of one frame's camera rays (camera.h). For each ray, the
// exact point on the hit triangle's plane (`pos`), the shading normal
// (corner normals interpolated where `corner_normals` is given, else the
// winding normal) and the geometric normal, both turned to the viewer's side,
// and the material (the hit object; -1 for a miss or the black back of a
// one-sided surface) with its emission. Misses leave zeros.
struct PrimaryScene {
    const double* v = nullptr;               // (F, 3, 3) triangle corners
    const double* ng = nullptr;              // (F, 3) unit winding normals
    const double* corner_normals = nullptr;  // (F, 3, 3) unit, or null
    const int32_t* object = nullptr;         // (F,)
    const uint8_t* two_sided = nullptr;      // (O,)
    const float* emission = nullptr;         // (O, 3)
};
// The hit of one ray (origin o, unit direction d) on triangle t (-1: none):
// point x on the triangle's plane in double, shading and geometric normals
// facing the ray's origin, material (-1: miss or a one-sided back) and the
// emission seen.
void primary_hit(const double o[3], const double d[3], int32_t t, const PrimaryScene& scene,
                 double x[3], float ns_out[3], float ng_out[3], int32_t* material, float le[3]);

// The BRDF used by the display for one pair of directions (exposed for tests):
// Lambertian rho/pi, a microfacet lobe (microfacet.h), or with a specular
// layer the Ashikhmin-Shirley pair (coupled diffuse + anisotropic Phong specular). k1 towards the
// light, k2 towards the viewer, n the normal; all unit vectors. Writes f (3,).
void shade_brdf(const ShadeMaterials& mats, int32_t m, const float n[3], const float k1[3],
                const float k2[3], float f[3]);
// The same with the diffuse albedo rd (3,) in place of the material's (a texture's).
void shade_brdf(const ShadeMaterials& mats, int32_t m, const float* rd, const float n[3],
                const float k1[3], const float k2[3], float f[3]);

}  // namespace voxgi
