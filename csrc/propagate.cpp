// propagate kernels (see propagate.h).
#include "propagate.h"

namespace voxgi {}
