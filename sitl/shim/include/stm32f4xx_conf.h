/*
 * drivecheck SITL shim: the STM32F4 standard peripheral library subset the portable firmware
 * modules touch (our own declarations). Timers count in virtual time (sitl_hal.c); the rest is
 * accepted and ignored.
 */
#ifndef SITL_STM32F4XX_CONF_H
#define SITL_STM32F4XX_CONF_H

#include <stdint.h>
#include "hal.h"

typedef enum { DISABLE = 0, ENABLE = !DISABLE } FunctionalState;
typedef enum { RESET = 0, SET = !RESET } FlagStatus, ITStatus;

typedef struct sitl_tim {
  volatile uint32_t CR1, CR2, SMCR, DIER, SR, EGR, CCMR1, CCMR2, CCER;
  volatile uint32_t CNT;
  volatile uint32_t PSC, ARR, RCR, CCR1, CCR2, CCR3, CCR4, BDTR, DCR, DMAR, OR;
} TIM_TypeDef;

/* Reading a timer first brings its counter up to the virtual time. */
TIM_TypeDef *sitl_tim(int n);
#define TIM1 (sitl_tim(1))
#define TIM2 (sitl_tim(2))
#define TIM3 (sitl_tim(3))
#define TIM4 (sitl_tim(4))
#define TIM5 (sitl_tim(5))
#define TIM6 (sitl_tim(6))
#define TIM7 (sitl_tim(7))
#define TIM8 (sitl_tim(8))
#define TIM12 (sitl_tim(12))

typedef struct {
  uint16_t TIM_Prescaler;
  uint16_t TIM_CounterMode;
  uint32_t TIM_Period;
  uint16_t TIM_ClockDivision;
  uint8_t TIM_RepetitionCounter;
} TIM_TimeBaseInitTypeDef;

#define TIM_CounterMode_Up ((uint16_t)0x0000)
#define TIM_CKD_DIV1 ((uint16_t)0x0000)
#define RCC_APB1Periph_TIM2 ((uint32_t)0x00000001)
#define RCC_APB1Periph_TIM3 ((uint32_t)0x00000002)
#define RCC_APB1Periph_TIM4 ((uint32_t)0x00000004)
#define RCC_APB1Periph_TIM5 ((uint32_t)0x00000008)
#define RCC_APB1Periph_TIM6 ((uint32_t)0x00000010)
#define RCC_APB1Periph_TIM7 ((uint32_t)0x00000020)

void TIM_TimeBaseInit(TIM_TypeDef *tim, TIM_TimeBaseInitTypeDef *init);
void TIM_Cmd(TIM_TypeDef *tim, FunctionalState state);
void TIM_SetCounter(TIM_TypeDef *tim, uint32_t counter);
void RCC_APB1PeriphClockCmd(uint32_t periph, FunctionalState state);
void RCC_APB2PeriphClockCmd(uint32_t periph, FunctionalState state);

/* Flash (the emulated EEPROM's backing store): accepted and ignored. */
#define FLASH_FLAG_EOP ((uint32_t)0x00000001)
#define FLASH_FLAG_OPERR ((uint32_t)0x00000002)
#define FLASH_FLAG_WRPERR ((uint32_t)0x00000010)
#define FLASH_FLAG_PGAERR ((uint32_t)0x00000020)
#define FLASH_FLAG_PGPERR ((uint32_t)0x00000040)
#define FLASH_FLAG_PGSERR ((uint32_t)0x00000080)
void FLASH_Unlock(void);
void FLASH_Lock(void);
void FLASH_ClearFlag(uint32_t flags);

#endif
