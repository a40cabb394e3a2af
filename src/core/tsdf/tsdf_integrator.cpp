#include "fisheye_mapping/core/tsdf/tsdf_integrator.h"

#include "fisheye_mapping/core/tsdf/tsdf_integrator_cl.h"
#include "fisheye_mapping/core/tsdf/tsdf_integrator_cpu.h"

namespace fisheye_mapping {

std::unique_ptr<TsdfIntegrator> makeTsdfIntegrator(const TsdfConfig& config) {
  switch (config.integrator) {
    case TsdfIntegratorKind::kOpenCl:
      return std::make_unique<TsdfIntegratorCl>(config);
    case TsdfIntegratorKind::kCpu:
      break;
  }
  return std::make_unique<TsdfIntegratorCpu>(config);
}

}  // namespace fisheye_mapping
