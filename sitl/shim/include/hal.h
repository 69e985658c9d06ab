/*
 * drivecheck SITL shim: the ChibiOS HAL and board API subset the portable firmware modules use
 * (our own declarations). Pins read as low, writes are ignored; the hardware drivers are not
 * compiled, the shim stands in for them (sitl_hw.c).
 */
#ifndef SITL_HAL_H
#define SITL_HAL_H

#include "ch.h"

typedef uint32_t ioportmask_t;
typedef uint32_t iomode_t;
typedef struct sitl_gpio {
  volatile uint32_t MODER, OTYPER, OSPEEDR, PUPDR, IDR, ODR;
  volatile uint16_t BSRRL, BSRRH;
  volatile uint32_t LCKR, AFR[2];
} GPIO_TypeDef;
typedef GPIO_TypeDef *ioportid_t;
typedef GPIO_TypeDef stm32_gpio_t;

/* Streams (chprintf targets) are opaque. */
typedef struct sitl_stream BaseSequentialStream;
extern GPIO_TypeDef sitl_gpio[9];
#define GPIOA (&sitl_gpio[0])
#define GPIOB (&sitl_gpio[1])
#define GPIOC (&sitl_gpio[2])
#define GPIOD (&sitl_gpio[3])
#define GPIOE (&sitl_gpio[4])
#define GPIOF (&sitl_gpio[5])
#define GPIOG (&sitl_gpio[6])
#define GPIOH (&sitl_gpio[7])
#define GPIOI (&sitl_gpio[8])

#define PAL_MODE_RESET 0
#define PAL_MODE_UNCONNECTED 0
#define PAL_MODE_INPUT 0
#define PAL_MODE_INPUT_PULLUP 1
#define PAL_MODE_INPUT_PULLDOWN 2
#define PAL_MODE_INPUT_ANALOG 3
#define PAL_MODE_OUTPUT_PUSHPULL 4
#define PAL_MODE_OUTPUT_OPENDRAIN 5
#define PAL_MODE_ALTERNATE(n) (0x100u | (uint32_t)(n))
#define PAL_STM32_OTYPE_OPENDRAIN 0x200u
#define PAL_STM32_OTYPE_PUSHPULL 0
#define PAL_STM32_OSPEED_HIGHEST 0x400u
#define PAL_STM32_OSPEED_MID1 0
#define PAL_STM32_OSPEED_MID2 0
#define PAL_STM32_PUDR_PULLUP 0x800u
#define PAL_STM32_PUDR_FLOATING 0
#define PAL_STM32_MODE_INPUT 0
#define PAL_STM32_MODE_ANALOG 0
#define PAL_LOW 0
#define PAL_HIGH 1
#define PAL_PORT_BIT(n) ((ioportmask_t)(1u << (n)))

void palSetPadMode(ioportid_t port, uint32_t pad, iomode_t mode);
void palSetGroupMode(ioportid_t port, ioportmask_t mask, uint32_t offset, iomode_t mode);
#define palReadPort(port) ((port)->IDR)
#define palReadPad(port, pad) ((int)(((port)->IDR >> (pad)) & 1u))
#define palSetPad(port, pad) ((port)->ODR |= PAL_PORT_BIT(pad))
#define palClearPad(port, pad) ((port)->ODR &= ~PAL_PORT_BIT(pad))
#define palTogglePad(port, pad) ((port)->ODR ^= PAL_PORT_BIT(pad))
#define palWritePad(port, pad, bit) \
  ((port)->ODR = ((port)->ODR & ~PAL_PORT_BIT(pad)) | ((uint32_t)((bit) & 1u) << (pad)))
#define palReadLatch(port) ((port)->ODR)

/* External interrupts (the PPS input): accepted and never fire. */
typedef uint32_t expchannel_t;
typedef struct sitl_ext_driver {
  int unused;
} EXTDriver;
extern EXTDriver EXTD1;
void extChannelEnable(EXTDriver *extp, expchannel_t channel);
void extChannelDisable(EXTDriver *extp, expchannel_t channel);

void halInit(void);
#define osalThreadSleepMilliseconds(ms) chThdSleepMilliseconds(ms)

#define CORTEX_PRIORITY_MASK(n) (n)
#define STM32_SYSCLK 168000000u

#endif
