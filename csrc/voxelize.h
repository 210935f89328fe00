// voxelize kernels.
#pragma once

namespace voxgi {}
