// propagate kernels.
#pragma once

namespace voxgi {}
