// Direct light: integer discrete rays from the emitters, deposited on the
// receivers (docs/design.md §5).
#include "shoot.h"

#include "shootmarch.h"

namespace voxgi {

namespace {

// The receiver-side deposit: receiver r of e's ray takes val[e] * cos_r *
// weight (irradiance, not yet divided by S), times the share of the line e
// covers and the share of the ray still travelling.
struct ReceiverSide {
    static constexpr bool kKeepShadowed = false;
    bool operator()(const Ray& r, const Family& F, const float* ve, const std::vector<RayHit>& recv,
                    std::vector<Deposit>& out) const {
        for (const RayHit& q : recv) {
            const double cr = double(q.c) * F.weight * r.alpha * q.T;
            out.push_back(Deposit{q.p, {ve[0] * cr, ve[1] * cr, ve[2] * cr}});
        }
        return true;
    }
};

}  // namespace

ShootCount shoot(const LineSystem& ls, const int32_t* emit, int64_t ne, const Family* fams,
                 int64_t nf, const float* val, double* hd, double* unfound, const ShootOptions& opt,
                 const StopCheck& stop) {
    if ((opt.object == nullptr) != (opt.sil_area == nullptr) ||
        (opt.object == nullptr) != (opt.back == nullptr))
        throw std::invalid_argument("object, sil_area and back go together");
    return shoot_march(ls, emit, ne, fams, nf, val, hd, unfound, opt, ReceiverSide(), stop);
}

}  // namespace voxgi
