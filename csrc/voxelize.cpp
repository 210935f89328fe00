// voxelize kernels (see voxelize.h).
#include "voxelize.h"

namespace voxgi {}
