# The example controller for QEMU's netduinoplus2 (STM32F405, Cortex-M4F), with Debian's
# gcc-arm-none-eabi and newlib. libmpack and mbedTLS are compiled from Debian's source
# packages (setup/50-device.sh unpacks them into $(BUILD)/deb-src); the msgpack-c packer
# and the libmpack header are the architecture-independent headers of the Debian packages.
ARM_CC := arm-none-eabi-gcc
ARM_SIZE := arm-none-eabi-size
DEBSRC := $(BUILD)/deb-src
ARM_DIR := $(BUILD)/arm
FIRMWARE_PASSWORD ?= op-secret
ARM_FLAGS := -mcpu=cortex-m4 -mthumb -mfloat-abi=hard -mfpu=fpv4-sp-d16 -Os -ffunction-sections \
  -fdata-sections -std=c99 -Wall -Wextra -Werror -Wno-unused-parameter -DEX_MCU \
  -DEX_TRAJ_CAPACITY=48 -DAD_LINK_TX_FRAMES=1u -DFIRMWARE_PASSWORD='"$(FIRMWARE_PASSWORD)"' \
  '-DMBEDTLS_CONFIG_FILE="mbedtls_config_m4.h"'
ARM_INC := -Iinclude -Isrc -Iexamples -Iport/stm32 -I$(ARM_DIR)/include -I$(DEBSRC)/mbedtls/include
MBEDTLS_SRC := $(addprefix $(DEBSRC)/mbedtls/library/,md.c sha256.c platform.c platform_util.c memory_buffer_alloc.c)
MPACK_SRC := $(DEBSRC)/libmpack/src/core.c $(DEBSRC)/libmpack/src/conv.c
FW_SRC := $(LIB_SRC) examples/example_controller.c port/stm32/board.c port/stm32/startup.c

.PHONY: arm size qemu-check
arm: $(ARM_DIR)/example.elf

$(ARM_DIR)/include/.done:
	@test -d $(DEBSRC)/mbedtls -a -d $(DEBSRC)/libmpack || { echo "run: bash setup/50-device.sh (Debian sources for the firmware)"; exit 1; }
	mkdir -p $(ARM_DIR)/include
	ln -sf /usr/include/mpack.h /usr/include/msgpack.h /usr/include/msgpack $(ARM_DIR)/include/
	touch $@

$(ARM_DIR)/example.elf: $(FW_SRC) $(HEADERS) port/stm32/stm32f405.ld port/stm32/mbedtls_config_m4.h $(ARM_DIR)/include/.done Makefile port/stm32/firmware.mk
	$(ARM_CC) $(ARM_FLAGS) $(ARM_INC) $(FW_SRC) -w $(MBEDTLS_SRC) $(MPACK_SRC) \
	  -Tport/stm32/stm32f405.ld -nostartfiles --specs=nano.specs --specs=nosys.specs \
	  -u _printf_float -Wl,--gc-sections -Wl,-Map=$(ARM_DIR)/example.map -lm -o $@

size: $(ARM_DIR)/example.elf
	$(ARM_SIZE) -A $< | grep -E '^\.(text|ARM|data|bss|stack) '
	$(ARM_SIZE) $<
