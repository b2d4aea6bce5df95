/* The simulated plant's hooks (hl_hal.h) where there is no simulated plant: the papers'
 * board (src/io_board.c) and the bridges built against a vendor's SDK, whose device a
 * person holds and whose real sample is a real object. */
#include "hl_hal.h"

void hal_plant_scene(float surface_m, int real_sample, const hal_sample *sample)
{
    (void)surface_m;
    (void)real_sample;
    (void)sample;
}
void hal_plant_home(float height_m) { (void)height_m; }
void hal_plant_task(int task) { (void)task; }
uint32_t hal_capabilities(void) { return 0u; } /* a physical contact, no simulation */
