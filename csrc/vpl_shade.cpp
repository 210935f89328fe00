// vpl_shade kernels (see vpl_shade.h).
#include "vpl_shade.h"

namespace voxgi {}
