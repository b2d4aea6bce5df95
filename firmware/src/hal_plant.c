/* The HAL's simulated-plant hooks (hl_hal.h) for every build that links src/plant.c: the
 * host build, the unit tests, the QEMU build and the tick bench. A board's HAL defines
 * them as no-ops instead (a person places the stylus; the real sample is a real object). */
#include "hl_contract.h"
#include "hl_hal.h"
#include "hl_plant.h"

void hal_plant_scene(float surface_m, int real_sample, const hal_sample *sample)
{
    plant_scene(surface_m, real_sample, sample->stiffness, sample->damping);
    plant_block(sample->block_mass, sample->support_k, sample->support_b);
}
void hal_plant_home(float height_m) { plant_home(height_m); }
void hal_plant_task(int task) { plant_task(task); }
/* nobody touches a physical surface, and the plant's noise comes from the seed it was
 * started with (hal_io_init) */
uint32_t hal_capabilities(void) { return HL_CAP_SIMULATED_CONTACT | HL_CAP_SEEDED; }
