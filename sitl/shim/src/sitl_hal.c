/*
 * drivecheck SITL shim: HAL, board and STM32 peripheral stand-ins (our own code).
 * GPIO reads as low and ignores writes; the basic timers count in virtual time; the flash is
 * not there and the emulated EEPROM is an empty in-memory table (the firmware then starts with
 * its compiled-in default configuration, as a board with an erased EEPROM does).
 */
#include "sitl.h"
#include "hal.h"
#include "stm32f4xx_conf.h"
#include "eeprom.h"

#include <stdio.h>
#include <string.h>

GPIO_TypeDef sitl_gpio[9];
EXTDriver EXTD1;

void halInit(void) {}
void palSetPadMode(ioportid_t port, uint32_t pad, iomode_t mode) {
  (void)port;
  (void)pad;
  (void)mode;
}
void palSetGroupMode(ioportid_t port, ioportmask_t mask, uint32_t offset, iomode_t mode) {
  (void)port;
  (void)mask;
  (void)offset;
  (void)mode;
}
void extChannelEnable(EXTDriver *extp, expchannel_t channel) {
  (void)extp;
  (void)channel;
}
void extChannelDisable(EXTDriver *extp, expchannel_t channel) {
  (void)extp;
  (void)channel;
}

/* ---- timers: the counter is derived from virtual time (APB1 timer clock 84 MHz) ---- */

#define SITL_TIMERS 13
static TIM_TypeDef tims[SITL_TIMERS];
static bool tim_running[SITL_TIMERS];
static uint64_t tim_start_us[SITL_TIMERS];

static int tim_index(TIM_TypeDef *tim) {
  int i = (int)(tim - tims);
  return (i >= 0 && i < SITL_TIMERS) ? i : 0;
}

TIM_TypeDef *sitl_tim(int n) {
  if (n < 0 || n >= SITL_TIMERS) n = 0;
  TIM_TypeDef *t = &tims[n];
  if (tim_running[n]) {
    uint64_t el = sitl_rt_now_us() - tim_start_us[n];
    uint64_t counts = el * 84ULL / ((uint64_t)t->PSC + 1ULL);
    uint64_t top = (uint64_t)t->ARR + 1ULL;
    t->CNT = (uint32_t)(top ? counts % top : counts);
  }
  return t;
}

void TIM_TimeBaseInit(TIM_TypeDef *tim, TIM_TimeBaseInitTypeDef *init) {
  tim->PSC = init->TIM_Prescaler;
  tim->ARR = init->TIM_Period;
}
void TIM_Cmd(TIM_TypeDef *tim, FunctionalState state) {
  int i = tim_index(tim);
  if (state == ENABLE && !tim_running[i]) {
    tim_running[i] = true;
    tim_start_us[i] = sitl_rt_now_us();
  } else if (state == DISABLE) {
    tim_running[i] = false;
  }
}
void TIM_SetCounter(TIM_TypeDef *tim, uint32_t counter) {
  (void)counter;
  int i = tim_index(tim);
  tim_start_us[i] = sitl_rt_now_us();
}
void RCC_APB1PeriphClockCmd(uint32_t periph, FunctionalState state) {
  (void)periph;
  (void)state;
}
void RCC_APB2PeriphClockCmd(uint32_t periph, FunctionalState state) {
  (void)periph;
  (void)state;
}

/* ---- flash and the emulated EEPROM ---- */

void FLASH_Unlock(void) {}
void FLASH_Lock(void) {}
void FLASH_ClearFlag(uint32_t flags) { (void)flags; }

static uint16_t ee_val[65536];
static uint8_t ee_set[65536];

uint16_t EE_Init(void) { return FLASH_COMPLETE; }
uint16_t EE_ReadVariable(uint16_t VirtAddress, uint16_t *Data) {
  if (!ee_set[VirtAddress]) return 1; /* variable not found */
  *Data = ee_val[VirtAddress];
  return 0;
}
uint16_t EE_WriteVariable(uint16_t VirtAddress, uint16_t Data) {
  ee_val[VirtAddress] = Data;
  ee_set[VirtAddress] = 1;
  return FLASH_COMPLETE;
}
