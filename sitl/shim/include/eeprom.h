/*
 * drivecheck SITL shim: the emulated-EEPROM API (ST application note AN3969) as the firmware's
 * configuration code calls it (our own declarations). Storage is in memory, empty at start, so
 * the firmware starts with its default configuration (sitl_hw.c).
 */
#ifndef SITL_EEPROM_H
#define SITL_EEPROM_H
#include <stdint.h>
#define EEPROM_START_ADDRESS ((uint32_t)0x08008000)
#define PAGE_SIZE ((uint32_t)0x4000)
#define NB_OF_VAR ((uint8_t)0xFF)
#define FLASH_COMPLETE 8
uint16_t EE_Init(void);
uint16_t EE_ReadVariable(uint16_t VirtAddress, uint16_t *Data);
uint16_t EE_WriteVariable(uint16_t VirtAddress, uint16_t Data);
#endif
